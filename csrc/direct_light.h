// Direct light on the records: shadow rays from each record's surface point
// to points drawn on the emitting triangles (docs/design.md §5). The rays are
// traced by Embree from Python; these kernels make them and sum the
// unoccluded contributions. No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "common.h"

namespace voxgi {

// The emitting triangles of a scene and the discrete distribution they are
// drawn from (in proportion to power, uniform in area inside each).
struct EmitterTriangles {
    int64_t count = 0;
    const double *corners = nullptr;    // (count, 3, 3) corner positions
    const double *normal = nullptr;     // (count, 3) unit winding normals
    const uint8_t *two_sided = nullptr; // (count,) nonzero: emits on both sides
    const double *radiance = nullptr;   // (count, 3) emitted radiance
    const double *cdf = nullptr;        // (count,) cumulative draw probability, last 1
    const double *density = nullptr;    // (count,) area density: probability / area
};

// The records receiving direct light and the samples each takes.
struct DirectLightQuery {
    int64_t records = 0;
    const double *point = nullptr;   // (records, 3) surface points
    const double *normal = nullptr;  // (records, 3) unit normals of the lit side
    const double *shift = nullptr;   // (records, 3) per-record shift of the sequence, in [0, 1)
    int64_t samples = 0;
    const double *sequence = nullptr;  // (samples, 3) points of [0, 1)^3
    double offset = 0.0;               // shadow-ray offset from both ends, scene units
};

// One shadow ray per record and sample, record-major: origin, unit direction
// and length (float32, as Embree takes them) and the RGB contribution
// L_e cos_x cos_y / (r^2 density) the ray brings if it is unoccluded. Rays
// that cannot contribute (a back face on either end, or closer than twice
// the offset) get length 0 and contribution 0.
void direct_light_rays(const EmitterTriangles &em, const DirectLightQuery &q, float *origin,
                       float *direction, float *length, float *contribution, int threads,
                       const StopCheck &stop);

// Per record: the mean RGB contribution of its unoccluded rays (irradiance)
// and the mean square of the luminance of each ray's contribution (for its
// variance). hit[k] != -1 marks ray k occluded (Embree's answer).
void direct_light_sum(int64_t records, int64_t samples, const float *contribution,
                      const int32_t *hit, double *irradiance, double *mean_square, int threads,
                      const StopCheck &stop);

}  // namespace voxgi
