// pybind11 bindings for the camera rays and their primary hits (camera.h).
#include <pybind11/stl.h>

#include <optional>
#include <utility>

#include "bind_shade.h"
#include "bind_texture.h"
#include "camera.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

voxgi::PrimaryScene make_primary_scene(const F64& tri_v, const F64& tri_ng,
                                       const std::optional<F64>& corner_normals,
                                       const I32& tri_object, const U8& obj_two_sided,
                                       const F32& obj_emission) {
    if (tri_v.ndim() != 3 || tri_v.shape(1) != 3 || tri_v.shape(2) != 3)
        throw py::value_error("tri_v must have shape (F, 3, 3)");
    const py::ssize_t F = tri_v.shape(0);
    check_2d(tri_ng, F, 3, "tri_ng");
    if (corner_normals && (corner_normals->ndim() != 3 || corner_normals->shape(0) != F ||
                           corner_normals->shape(1) != 3 || corner_normals->shape(2) != 3))
        throw py::value_error("corner_normals must have shape (F, 3, 3) like tri_v");
    check_1d(tri_object, F, "tri_object");
    check_2d(obj_emission, -1, 3, "obj_emission");
    const py::ssize_t O = obj_emission.shape(0);
    check_1d(obj_two_sided, O, "obj_two_sided");
    const int32_t* po = tri_object.data();
    for (py::ssize_t i = 0; i < F; ++i)
        if (po[i] < 0 || po[i] >= O)
            throw py::value_error("tri_object: object " + std::to_string(po[i]) +
                                  " out of range (" + std::to_string(O) + " objects)");
    voxgi::PrimaryScene sc;
    sc.v = tri_v.data();
    sc.ng = tri_ng.data();
    sc.corner_normals = corner_normals ? corner_normals->data() : nullptr;
    sc.object = po;
    sc.two_sided = obj_two_sided.data();
    sc.emission = obj_emission.data();
    return sc;
}

// (3,) finite vector `name` into out.
// The mirrors of camera_hits and camera_emission, or none where no object is
// one (obj_mirror absent or all 0).
std::optional<voxgi::CameraMirrors> make_mirrors(const std::optional<U8>& obj_mirror,
                                                 const std::optional<F32>& obj_lobe,
                                                 uint64_t mirror_seed, double eps,
                                                 py::ssize_t objects) {
    if (!obj_mirror) return std::nullopt;
    check_1d(*obj_mirror, objects, "obj_mirror");
    const uint8_t* pm = obj_mirror->data();
    bool any = false;
    for (py::ssize_t i = 0; i < objects; ++i) any |= pm[i] != 0;
    if (!any) return std::nullopt;
    if (!obj_lobe) throw py::value_error("obj_mirror needs obj_lobe");
    check_2d(*obj_lobe, objects, voxgi::kLobeWidth, "obj_lobe");
    if (!(eps > 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and > 0");
    voxgi::CameraMirrors M;
    M.is_mirror = pm;
    M.lobe = reinterpret_cast<const voxgi::MicrofacetLobe*>(obj_lobe->data());
    for (py::ssize_t i = 0; i < objects; ++i) {
        const voxgi::MicrofacetLobe& L = M.lobe[i];
        if (pm[i] && (L.kind != 2.f || !(L.alpha >= 1e-4f && L.alpha <= 4.f)))
            throw py::value_error("obj_lobe: object " + std::to_string(i) +
                                  " is a mirror but its row is not a conductor's lobe (kind 2, "
                                  "alpha in [1e-4, 4])");
    }
    M.seed = mirror_seed;
    M.eps = eps;
    return M;
}

void vector3(const F64& a, const char* name, double out[3]) {
    check_1d(a, 3, name);
    for (int c = 0; c < 3; ++c) {
        out[c] = a.data()[c];
        if (!std::isfinite(out[c])) throw py::value_error(std::string(name) + " must be finite");
    }
}

// The camera of camera_rays and camera_hits, checked.
voxgi::PixelCamera make_camera(const F64& eye, const F64& right, const F64& up, const F64& forward,
                               double tan_half_fov, int64_t width, int64_t height, double aperture,
                               double focus) {
    voxgi::PixelCamera cam;
    vector3(eye, "eye", cam.eye);
    vector3(right, "right", cam.right);
    vector3(up, "up", cam.up);
    vector3(forward, "forward", cam.forward);
    if (!(tan_half_fov > 0.0) || !std::isfinite(tan_half_fov))
        throw py::value_error("tan_half_fov must be finite and > 0");
    if (width < 1 || height < 1 || width > (int64_t(1) << 20) || height > (int64_t(1) << 20))
        throw py::value_error("width and height must be in [1, 2^20]");
    if (!(aperture >= 0.0) || !std::isfinite(aperture))
        throw py::value_error("aperture must be finite and >= 0");
    if (aperture > 0.0 && (!(focus > 0.0) || !std::isfinite(focus)))
        throw py::value_error("focus must be finite and > 0 with an aperture");
    cam.tan_half_fov = tan_half_fov;
    cam.width = width;
    cam.height = height;
    cam.aperture = aperture;
    cam.focus = focus;
    return cam;
}

// A frame's sub-pixel offset and lens point, checked.
void frame_sample(std::pair<double, double> offset, std::pair<double, double> lens, double off[2],
                  double ln[2]) {
    off[0] = offset.first, off[1] = offset.second, ln[0] = lens.first, ln[1] = lens.second;
    for (double v : {off[0], off[1], ln[0], ln[1]})
        if (!std::isfinite(v)) throw py::value_error("offset and lens must be finite");
}

py::tuple camera_rays_py(const F64& eye, const F64& right, const F64& up, const F64& forward,
                         double tan_half_fov, int64_t width, int64_t height, double aperture,
                         double focus, std::pair<double, double> offset,
                         std::pair<double, double> lens, int threads) {
    const voxgi::PixelCamera cam =
        make_camera(eye, right, up, forward, tan_half_fov, width, height, aperture, focus);
    double off[2], ln[2];
    frame_sample(offset, lens, off, ln);
    const py::ssize_t P = width * height;
    F64 org({P, py::ssize_t(3)}), dir({P, py::ssize_t(3)});
    double *po = org.mutable_data(), *pd = dir.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::camera_rays(cam, off, ln, po, pd, threads, stop);
    }
    return py::make_tuple(org, dir);
}

py::tuple camera_hits_py(const F64& eye, const F64& right, const F64& up, const F64& forward,
                         double tan_half_fov, int64_t width, int64_t height, double aperture,
                         double focus, std::pair<double, double> offset,
                         std::pair<double, double> lens, const F64& tri_v, const F64& tri_ng,
                         const std::optional<F64>& corner_normals, const I32& tri_object,
                         const U8& obj_two_sided, const F32& obj_emission,
                         const voxgi::RayScene& scene, int threads,
                         const std::optional<F32>& obj_albedo,
                         const std::optional<std::vector<U8>>& tex_texels,
                         const std::optional<F64>& tex_info, const std::optional<I32>& obj_texture,
                         const std::optional<F32>& corner_uv, const std::optional<U8>& obj_mirror,
                         const std::optional<F32>& obj_lobe, uint64_t mirror_seed, double eps,
                         std::pair<double, double> mirror_point) {
    const voxgi::PixelCamera cam =
        make_camera(eye, right, up, forward, tan_half_fov, width, height, aperture, focus);
    double off[2], ln[2];
    frame_sample(offset, lens, off, ln);
    const voxgi::PrimaryScene sc =
        make_primary_scene(tri_v, tri_ng, corner_normals, tri_object, obj_two_sided, obj_emission);
    check_scene(scene, tri_v.shape(0));
    const py::ssize_t O = obj_emission.shape(0);
    if (obj_albedo) check_2d(*obj_albedo, O, 3, "obj_albedo");
    const auto tex = make_textures(tex_texels, tex_info, obj_texture, corner_uv, tri_v.shape(0), O);
    if (tex && !obj_albedo) throw py::value_error("textures need obj_albedo");
    const py::ssize_t P = width * height;
    py::object albedo = py::none();
    float* pa = nullptr;
    if (obj_albedo) {
        F32 a({P, py::ssize_t(3)});
        pa = a.mutable_data();
        albedo = a;
    }
    const float* oa = obj_albedo ? obj_albedo->data() : nullptr;
    F64 pos({P, py::ssize_t(3)});
    F32 normal({P, py::ssize_t(3)}), ng({P, py::ssize_t(3)}), wo({P, py::ssize_t(3)}),
        le({P, py::ssize_t(3)});
    I32 material(P), prim(P);
    double* ppos = pos.mutable_data();
    float *pn = normal.mutable_data(), *pg = ng.mutable_data(), *pw = wo.mutable_data(),
          *pl = le.mutable_data();
    int32_t* pm = material.mutable_data();
    // what the sheets before each hit let through: only a scene with sheets has it
    auto mirrors = make_mirrors(obj_mirror, obj_lobe, mirror_seed, eps, O);
    if (mirrors) {
        const double u[2] = {mirror_point.first, mirror_point.second};
        for (int a = 0; a < 2; ++a) {
            if (!(u[a] >= 0.0 && u[a] < 1.0))
                throw py::value_error("mirror_point must lie in [0, 1)^2");
            mirrors->point[a] = u[a];
        }
    }
    // what the sheets and mirrors before each hit let through: only a scene
    // with either has it
    const bool has_through = scene.has_sheets() || mirrors.has_value();
    F32 through({has_through ? P : py::ssize_t(0), py::ssize_t(3)});
    float* pt = has_through ? through.mutable_data() : nullptr;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::camera_hits(cam, off, ln, scene, sc, ppos, pn, pg, pw, pm, pl, prim.mutable_data(),
                           pt, threads, stop, tex ? &tex->surface : nullptr, oa, pa,
                           mirrors ? &*mirrors : nullptr);
    }
    return py::make_tuple(pos, normal, ng, wo, material, le, prim,
                          has_through ? py::object(through) : py::object(py::none()), albedo);
}

py::tuple camera_emission_py(const F64& eye, const F64& right, const F64& up, const F64& forward,
                             double tan_half_fov, int64_t width, int64_t height, double aperture,
                             double focus, const I64& pixels, const F64& samples, const F64& tri_v,
                             const F64& tri_ng, const std::optional<F64>& corner_normals,
                             const I32& tri_object, const U8& obj_two_sided,
                             const F32& obj_emission, const voxgi::RayScene& scene, int threads,
                             const std::optional<U8>& obj_mirror,
                             const std::optional<F32>& obj_lobe, uint64_t mirror_seed, double eps) {
    const voxgi::PixelCamera cam =
        make_camera(eye, right, up, forward, tan_half_fov, width, height, aperture, focus);
    const voxgi::PrimaryScene sc =
        make_primary_scene(tri_v, tri_ng, corner_normals, tri_object, obj_two_sided, obj_emission);
    check_scene(scene, tri_v.shape(0));
    check_1d(pixels, -1, "pixels");
    if (samples.ndim() != 2 || (samples.shape(1) != 4 && samples.shape(1) != 6))
        throw py::value_error("samples must have shape (K, 4) or (K, 6)");
    const int sw = int(samples.shape(1));
    const py::ssize_t M = pixels.shape(0), K = samples.shape(0);
    const int64_t* pp = pixels.data();
    for (py::ssize_t m = 0; m < M; ++m)
        if (pp[m] < 0 || pp[m] >= width * height)
            throw py::value_error("pixels: pixel " + std::to_string(pp[m]) + " outside the " +
                                  std::to_string(width) + "x" + std::to_string(height) + " image");
    const double* ps = samples.data();
    for (py::ssize_t k = 0; k < K; ++k) {
        const double* s = ps + sw * k;
        if (sw == 6 && !(s[4] >= 0.0 && s[4] < 1.0 && s[5] >= 0.0 && s[5] < 1.0))
            throw py::value_error("samples: mirror numbers " + std::to_string(k) +
                                  " outside [0, 1)^2");
        if (!(s[0] >= 0.0 && s[0] <= 1.0 && s[1] >= 0.0 && s[1] <= 1.0))
            throw py::value_error("samples: offset " + std::to_string(k) + " outside [0, 1]^2");
        if (!(s[2] * s[2] + s[3] * s[3] <= 1.0 + 1e-9))
            throw py::value_error("samples: lens point " + std::to_string(k) +
                                  " outside the unit disc");
    }
    const py::ssize_t N = M * K;
    F32 le({N, py::ssize_t(3)}), wo({N, py::ssize_t(3)});
    I32 prim(N);
    const auto mirrors =
        make_mirrors(obj_mirror, obj_lobe, mirror_seed, eps, obj_emission.shape(0));
    const bool has_through = scene.has_sheets() || mirrors.has_value();
    F32 through({has_through ? N : py::ssize_t(0), py::ssize_t(3)});
    float* pt = has_through ? through.mutable_data() : nullptr;
    float *pl = le.mutable_data(), *pw = wo.mutable_data();
    int32_t* pr = prim.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::camera_emission(cam, pp, M, ps, K, sw, scene, sc, pl, pw, pr, pt, threads, stop,
                               mirrors ? &*mirrors : nullptr);
    }
    return py::make_tuple(le, wo, prim, has_through ? py::object(through) : py::object(py::none()));
}

}  // namespace

void bind_camera(py::module_& m) {
    m.def("camera_rays", &camera_rays_py, "eye"_a.noconvert(), "right"_a.noconvert(),
          "up"_a.noconvert(), "forward"_a.noconvert(), "tan_half_fov"_a, "width"_a, "height"_a,
          "aperture"_a, "focus"_a, "offset"_a, "lens"_a, "threads"_a = 0,
          R"doc(Every pixel's camera ray through sub-pixel offset (x right, y down, in
[0, 1)^2) and lens point (unit disc, scaled by aperture): origins and unit
directions (P, 3) float64, P = width * height, row-major from the top-left
pixel; right, up, forward the camera's unit frame (Camera.frame), a pinhole
for aperture 0, else a thin lens focused at distance focus along forward.)doc");

    m.def("camera_hits", &camera_hits_py, "eye"_a.noconvert(), "right"_a.noconvert(),
          "up"_a.noconvert(), "forward"_a.noconvert(), "tan_half_fov"_a, "width"_a, "height"_a,
          "aperture"_a, "focus"_a, "offset"_a, "lens"_a, "tri_v"_a.noconvert(),
          "tri_ng"_a.noconvert(), "corner_normals"_a.noconvert(), "tri_object"_a.noconvert(),
          "obj_two_sided"_a.noconvert(), "obj_emission"_a.noconvert(), "scene"_a, "threads"_a = 0,
          "obj_albedo"_a.noconvert() = py::none(), "tex_texels"_a = py::none(),
          "tex_info"_a.noconvert() = py::none(), "obj_texture"_a.noconvert() = py::none(),
          "corner_uv"_a.noconvert() = py::none(), "obj_mirror"_a.noconvert() = py::none(),
          "obj_lobe"_a.noconvert() = py::none(), "mirror_seed"_a = 0, "eps"_a = 0.0,
          "mirror_point"_a = std::make_pair(0.5, 0.5),
          R"doc(Every pixel's camera ray (camera_rays, with eye in the scene's frame), its
first hit in scene (a RayScene built from tri_v) and the hit: the exact point
on the hit triangle's plane pos (P, 3) float64, normal, ng and wo (the
unit direction back to the eye) (P, 3) float32, the shading and geometric
normals turned to the viewer, material (P,) int32 (-1: a miss or a one-sided
back), its emission (P, 3) float32, the hit triangle (P,) int32 (-1: none),
P = width * height, row-major from the top-left pixel, where the scene has
sheets the product of their transmittances before the hit (P, 3) float32
(None otherwise) and, with obj_albedo (O, 3) float32, each hit's albedo
(P, 3) float32 (else None): its object's, or its texture's at the hit point
where the textures (tex_texels, a list of (H, W, 3) uint8; tex_info (T, 12)
float64: filter, wrap, raw, to_uv, factor; obj_texture (O,) int32, -1: none;
corner_uv (F, 3, 2) float32) give the object one. With obj_mirror (O,)
uint8 (nonzero: a smooth mirror) and obj_lobe (O, LOBE_WIDTH) float32 (a
mirror's row a conductor's lobe), a ray that meets a mirror goes on in a
direction drawn from its lobe (the first from mirror_point in [0, 1)^2
rotated by a hash of mirror_seed and the pixel, the next from a stream of
that hash), eps off it, through up to 4 mirrors: the outputs are those of the hit it ends
on, wo the way back along its last link, and `through` (then always given)
includes the mirrors' f cos / pdf.)doc");

    m.def("camera_emission", &camera_emission_py, "eye"_a.noconvert(), "right"_a.noconvert(),
          "up"_a.noconvert(), "forward"_a.noconvert(), "tan_half_fov"_a, "width"_a, "height"_a,
          "aperture"_a, "focus"_a, "pixels"_a.noconvert(), "samples"_a.noconvert(),
          "tri_v"_a.noconvert(), "tri_ng"_a.noconvert(), "corner_normals"_a.noconvert(),
          "tri_object"_a.noconvert(), "obj_two_sided"_a.noconvert(), "obj_emission"_a.noconvert(),
          "scene"_a, "threads"_a = 0, "obj_mirror"_a.noconvert() = py::none(),
          "obj_lobe"_a.noconvert() = py::none(), "mirror_seed"_a = 0, "eps"_a = 0.0,
          R"doc(The emission seen by K camera samples through each of M pixels (pixels
(M,) int64, row-major indices), the camera as in camera_hits; samples (K, 4)
float64: the sub-pixel offset in [0, 1]^2 (x right, y down) and the lens
point on the unit disc; or (K, 6): then also the first mirror link's
numbers in [0, 1)^2 (rotated by a hash of mirror_seed and the pixel). Returns, at index m * K + k: the first hit's
emission (M * K, 3) float32 (0 on a miss or a one-sided back), wo (the unit
direction back to the eye) (M * K, 3) float32, the hit triangle (M * K,)
int32 (-1: none) and, where the scene has sheets, what they let through
before the hit (M * K, 3) float32 (None otherwise). obj_mirror, obj_lobe,
mirror_seed and eps as in camera_hits (a stream per sample).)doc");
}
