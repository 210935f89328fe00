// Direct light on the records (docs/design.md §5): from each record's surface
// point, shadow rays to points drawn on the emitting triangles (light
// sampling) and rays in cosine-distributed directions (hemisphere sampling),
// combined by the power heuristic (Veach 1997), so that neither a small lamp far away
// nor a large emitter next to the record gives unbounded variance. With a
// RayScene, direct_light_traced makes, traces and sums the rays record by
// record; without one, Embree traces them from Python between
// direct_light_rays and direct_light_sum. No pybind11 here: plain pointers
// and sizes.
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
};

// The rays of every record and sample, record-major, as Embree takes them
// (float32 origin, unit direction, length). Light rays end an offset short of
// their emitter point and are asked "occluded?"; their `contribution` is
// the RGB they add if unoccluded (already weighted). Hemisphere rays are
// infinite and asked "which triangle first?". Light rays that cannot
// contribute (a back face at either end, or closer than twice the offset)
// get length 0.
void direct_light_rays(const EmitterTriangles& em, const DirectLightQuery& q, float* light_origin,
                       float* light_direction, float* light_length, float* contribution,
                       float* hemi_origin, float* hemi_direction, int threads,
                       const StopCheck& stop);

// Per record: the direct irradiance (the mean over its samples of the pair
// light + hemisphere sample) and the mean square of that pair's luminance
// (for its variance). light_hit[k] != -1: light ray k occluded. hemi_hit[k]:
// the scene triangle hemisphere ray k met first (-1: none), hemi_u/v its
// barycentrics there; emitter_of[t]: the emitter index of scene triangle t,
// or -1.
void direct_light_sum(const EmitterTriangles& em, const DirectLightQuery& q,
                      const float* contribution, const int32_t* light_hit,
                      const float* hemi_direction, const int32_t* hemi_hit, const float* hemi_u,
                      const float* hemi_v, const int32_t* emitter_of, int64_t scene_triangles,
                      double* irradiance, double* mean_square, int threads, const StopCheck& stop);

// direct_light_rays, the rays traced in `scene` (built from the scene's
// triangles, which emitter_of indexes) and direct_light_sum, record by
// record without the ray arrays. With `emitter_scene` (the emitter
// triangles alone, in the order of `em`), a hemisphere ray is traced
// against the emitters, and against the scene only up to the nearest
// emitter it meets (an offset short of it); without, to its first hit in
// the scene. Either way the sums are those of the two passes, but that with
// `emitter_scene` a surface within the offset in front of an emitter does
// not hide it from the hemisphere ray, as it does not hide it from the
// light rays.
void direct_light_traced(const EmitterTriangles& em, const DirectLightQuery& q,
                         const int32_t* emitter_of, const RayScene& scene,
                         const RayScene* emitter_scene, double* irradiance, double* mean_square,
                         int threads, const StopCheck& stop);

}  // namespace voxgi
