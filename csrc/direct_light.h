// Direct light on the records (docs/design.md §5): from each record's surface
// point, shadow rays to points drawn on the emitting triangles (light
// sampling) and rays in cosine-distributed directions (hemisphere sampling),
// combined by the power heuristic (Veach 1997), so that neither a small lamp far away
// nor a large emitter next to the record gives unbounded variance.
// direct_light_traced makes, traces and sums the rays record by record
// against a RayScene. No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "ray_scene.h"
#include "util/parallel.h"

namespace voxgi {

// The emitting triangles of a scene and the distribution light samples are
// drawn from (a triangle in proportion to power, a point uniform in area).
struct EmitterTriangles {
    int64_t count = 0;
    const double* corners = nullptr;     // (count, 3, 3) corner positions
    const double* normal = nullptr;      // (count, 3) unit winding normals
    const uint8_t* two_sided = nullptr;  // (count,) nonzero: emits on both sides
    const double* radiance = nullptr;    // (count, 3) emitted radiance
    const double* cdf = nullptr;         // (count,) cumulative draw probability, last 1
    const double* density = nullptr;  // (count,) area density of a light sample: probability / area
};

// The records lit and the samples each takes: `samples` light samples and
// as many hemisphere samples, from one shared point set shifted per record
// (Cranley-Patterson rotation), so each record's samples are stratified.
struct DirectLightQuery {
    int64_t records = 0;
    const double* point = nullptr;   // (records, 3) surface points
    const double* normal = nullptr;  // (records, 3) unit normals of the lit side
    const double* shift = nullptr;   // (records, 5) per-record shift, in [0, 1)
    int64_t samples = 0;
    const double* sequence = nullptr;  // (samples, 5) points of [0, 1)^5
    double offset = 0.0;               // ray offset from the surfaces, scene units
    // (records,) or null (all 1): the factor on the hemisphere sampling's
    // density in the power heuristic, each record's own. Any positive
    // factors keep the estimate unbiased (the two weights of a direction
    // still sum to 1); the one that minimises the variance weighs each
    // strategy by the inverse of its variance (Grittmann et al. 2019), so
    // that in an enclosure of emitters, where a cosine-distributed ray
    // always finds the same radiance, the hemisphere samples carry it.
    const double* hemisphere_scale = nullptr;
    // (T, kIncidenceNodes, 3) and (records,), or null: each sample's light
    // weighed by its record's incidence response at the sample's cosine
    // (incidence_response.h), so that the sum is the light the record
    // reflects over its mean albedo.
    const float* response = nullptr;
    const int32_t* response_row = nullptr;
    // (T, kIncidenceNodes, 3) or null: the same rows for the light the
    // record's diffuse base reflects, over its mean albedo (base_irradiance)
    const float* response_base = nullptr;
};

// Per record: the direct irradiance (the mean over its samples of the pair
// light + hemisphere sample) and the mean square of that pair's luminance
// (for its variance); with `strategy_variance` (records, 2; nullable) also
// the variance of the luminance of the light samples' and the hemisphere
// samples' own estimates (each alone, unweighted), the rays traced in
// `scene` (built from the scene's
// triangles, which emitter_of indexes: the emitter index of each scene
// triangle, or -1). A light ray ends an offset short of its emitter point
// and brings the sample's weighted light unless occluded; one that cannot
// contribute (a back face at either end, or closer than twice the offset)
// is not traced. A hemisphere ray brings its emitter's power-heuristic
// share when an emitter is the first thing it meets. With `emitter_scene`
// (the emitter triangles alone, in the order of `em`), a hemisphere ray is
// traced against the emitters, and against the scene only up to the
// nearest emitter it meets (an offset short of it); without, to its first
// hit in the scene. With `emitter_scene` a surface within the offset in
// front of an emitter does not hide it from the hemisphere ray, as it does
// not hide it from the light rays.
// With `base_irradiance` (records, 3; nullable) also the samples' sum
// weighed by response_base.
void direct_light_traced(const EmitterTriangles& em, const DirectLightQuery& q,
                         const int32_t* emitter_of, const RayScene& scene,
                         const RayScene* emitter_scene, double* irradiance, double* mean_square,
                         double* strategy_variance, double* base_irradiance, int threads,
                         const StopCheck& stop);

}  // namespace voxgi
