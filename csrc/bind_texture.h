// pybind11 checks of the surface textures the display and the voxelization
// read (texture.h): a list of texel arrays, a table of their filters, wraps,
// transforms and factors, each object's texture and each corner's UV.
#pragma once

#include <pybind11/stl.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "bind_common.h"
#include "texture.h"

namespace voxgi::py_helpers {

// Columns of tex_info: filter, wrap, raw, to_uv (2 x 3), factor (3).
constexpr py::ssize_t kTextureInfo = 12;

// The textures checked; holds the texel arrays while a kernel reads them.
struct TextureArgs {
    std::vector<U8> texels;
    std::vector<voxgi::Texture> textures;
    voxgi::SurfaceTextures surface;
};

// All four given, or none (nullopt). F triangles, O objects.
inline std::optional<TextureArgs> make_textures(const std::optional<std::vector<U8>>& tex_texels,
                                                const std::optional<F64>& tex_info,
                                                const std::optional<I32>& obj_texture,
                                                const std::optional<F32>& corner_uv, py::ssize_t F,
                                                py::ssize_t O) {
    const int given = int(tex_texels.has_value()) + int(tex_info.has_value()) +
                      int(obj_texture.has_value()) + int(corner_uv.has_value());
    if (given == 0) return std::nullopt;
    if (given != 4)
        throw py::value_error("tex_texels, tex_info, obj_texture and corner_uv go together");
    TextureArgs a;
    a.texels = *tex_texels;
    const py::ssize_t T = py::ssize_t(a.texels.size());
    check_2d(*tex_info, T, kTextureInfo, "tex_info");
    check_1d(*obj_texture, O, "obj_texture");
    if (corner_uv->ndim() != 3 || corner_uv->shape(0) != F || corner_uv->shape(1) != 3 ||
        corner_uv->shape(2) != 2)
        throw py::value_error("corner_uv must have shape (F, 3, 2)");
    const double* info = tex_info->data();
    for (py::ssize_t k = 0; k < T; ++k) {
        const U8& px = a.texels[k];
        if (px.ndim() != 3 || px.shape(2) != 3 || px.shape(0) < 1 || px.shape(1) < 1)
            throw py::value_error("tex_texels[" + std::to_string(k) +
                                  "] must have shape (H, W, 3)");
        const double* row = info + kTextureInfo * k;
        for (py::ssize_t c = 0; c < kTextureInfo; ++c)
            if (!std::isfinite(row[c]))
                throw py::value_error("tex_info[" + std::to_string(k) + "] must be finite");
        if (row[0] != 0.0 && row[0] != 1.0)
            throw py::value_error("tex_info: filter must be 0 or 1");
        if (row[1] != 0.0 && row[1] != 1.0 && row[1] != 2.0)
            throw py::value_error("tex_info: wrap must be 0, 1 or 2");
        voxgi::Texture t;
        t.height = px.shape(0);
        t.width = px.shape(1);
        t.texels = px.data();
        t.filter = voxgi::Texture::Filter(int(row[0]));
        t.wrap = voxgi::Texture::Wrap(int(row[1]));
        t.raw = row[2] != 0.0;
        for (int c = 0; c < 6; ++c) t.to_uv[c] = row[3 + c];
        for (int c = 0; c < 3; ++c) t.factor[c] = float(row[9 + c]);
        a.textures.push_back(t);
    }
    const int32_t* ot = obj_texture->data();
    for (py::ssize_t o = 0; o < O; ++o)
        if (ot[o] < -1 || ot[o] >= T)
            throw py::value_error("obj_texture: object " + std::to_string(o) + " names texture " +
                                  std::to_string(ot[o]) + " of " + std::to_string(T));
    a.surface.textures = a.textures.data();
    a.surface.count = T;
    a.surface.object_texture = ot;
    a.surface.corner_uv = corner_uv->data();
    return a;
}

}  // namespace voxgi::py_helpers
