// The reflected light of one display frame, averaged over neighbouring
// pixels that see the same smooth surface (docs/design.md §6).
#pragma once

#include <cstdint>

#include "util/parallel.h"

namespace voxgi {

// One frame's camera hits, row-major (width x height).
struct FilterPixels {
    int64_t width = 0, height = 0;
    const int32_t* material = nullptr;  // (P,) hit object, -1: nothing shaded
    const float* normal = nullptr;      // (P, 3) unit shading normals facing the viewer
    const double* pos = nullptr;        // (P, 3) hit points
    const uint8_t* glossy = nullptr;    // (O,) per material: its light is left as it is
    int32_t n_materials = 0;
    double eye[3] = {0.0, 0.0, 0.0};  // the camera, in the frame of pos
    double pixel_angle = 0.0;         // a pixel's width over its distance, at the axis
};

// Adds into out (P, 3), for every pixel p, the mean of in (P, 3) over p and
// the pairs of pixels q, q' of the (2 radius + 1)² square around it that lie
// point-symmetric about p (q' = 2p - q) and both see p's surface: the same
// material, normals within about 25 degrees (n_p . n_q > 0.9), within two
// pixel footprints of p's tangent plane and within 3 (radius + 1) footprints
// of p. Pairs keep a linear gradient of the light unchanged beside an
// outline or the image border. A pixel of a glossy material, or with nothing
// shaded, adds its own value unchanged.
void geometry_filter(const FilterPixels& px, int radius, const float* in, float* out, int threads,
                     const StopCheck& stop);

}  // namespace voxgi
