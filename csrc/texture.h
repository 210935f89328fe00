// UV-mapped bitmap textures of a surface's diffuse albedo (docs/design.md
// §6, §12): looked up at a camera or gather-ray hit, and averaged over the
// surface a voxel record stands for. No pybind11 here.
#pragma once

#include <cstdint>

namespace voxgi {

// One bitmap: 8-bit RGB texels, row 0 the image's top row, as Mitsuba 3 reads
// an 8-bit image: each texel decoded to linear (sRGB, or code / 255 when raw)
// before it is filtered, so that the filter interpolates linear values.
struct Texture {
    int64_t width = 0, height = 0;
    const uint8_t* texels = nullptr;  // (height, width, 3)
    enum Filter : int32_t { kNearest = 0, kBilinear = 1 } filter = kBilinear;
    enum Wrap : int32_t { kRepeat = 0, kMirror = 1, kClamp = 2 } wrap = kRepeat;
    bool raw = false;
    // (u', v') = M (u, v, 1): the texture's to_uv, rows of a 2 x 3 affine map
    double to_uv[6] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0};
    float factor[3] = {1.0f, 1.0f, 1.0f};  // multiplies the filtered texel
};

// The textures of a scene's surfaces: which object reads which texture, and
// the UVs of every triangle's corners.
struct SurfaceTextures {
    const Texture* textures = nullptr;  // (T,)
    int64_t count = 0;
    const int32_t* object_texture = nullptr;  // (O,) texture of each object, -1: none
    const float* corner_uv = nullptr;         // (F, 3, 2) UVs of each triangle's corners
};

// The filtered albedo of texture t at (u, v) (before to_uv), into out (3,).
void texture_eval(const Texture& t, double u, double v, float out[3]);

// Barycentric weights (b1, b2) of x in triangle (v0, v1, v2), x on its plane.
void barycentric(const double v0[3], const double v1[3], const double v2[3], const double x[3],
                 double& b1, double& b2);

// The albedo of triangle `tri` (object `obj`) at barycentric weights (b1, b2),
// into out; false when the object has no texture (out untouched).
bool surface_albedo(const SurfaceTextures& s, int64_t tri, int32_t obj, double b1, double b2,
                    float out[3]);

// The texture's mean over the part of a triangle given by three UV corners
// (the mean of the filtered texture over that UV triangle, by the midpoint
// rule on k² congruent sub-triangles, k growing with the texels the triangle
// covers, at most kMaxSplit), into mean (3,).
constexpr int kMaxSplit = 32;
constexpr double kSamplesPerTexel = 16.0;
void texture_triangle_mean(const Texture& t, const double uv[3][2], double mean[3]);

}  // namespace voxgi
