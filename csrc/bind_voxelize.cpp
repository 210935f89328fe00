// pybind11 bindings for the voxelize kernels (the only pybind11 code for them).
#include <algorithm>
#include <chrono>
#include <cstring>
#include <memory>

#include "bind_common.h"
#include "bind_texture.h"
#include "voxelize.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

using B8 = py::array_t<bool, py::array::c_style>;

py::dict voxelize_py(const F64& triangles, const I32& tri_object, const B8& two_sided,
                     const F32& albedo, const F32& emission, const F64& origin, double pitch,
                     const I32& dims, double cos_cluster, bool cut, double eps, int threads,
                     const py::object& progress, const std::optional<std::vector<U8>>& tex_texels,
                     const std::optional<F64>& tex_info, const std::optional<I32>& obj_texture,
                     const std::optional<F32>& corner_uv) {
    if (triangles.ndim() != 3 || triangles.shape(1) != 3 || triangles.shape(2) != 3)
        throw py::value_error("triangles must have shape (F, 3, 3)");
    const py::ssize_t F = triangles.shape(0);
    check_1d(tri_object, F, "tri_object");
    check_1d(two_sided, -1, "two_sided");
    const py::ssize_t O = two_sided.shape(0);
    check_2d(albedo, O, 3, "albedo");
    check_2d(emission, O, 3, "emission");
    check_1d(origin, 3, "origin");
    check_1d(dims, 3, "dims");
    if (F > 0 && O == 0) throw py::value_error("two_sided: at least one object is needed");
    if (O >= (py::ssize_t(1) << 31)) throw py::value_error("too many objects");
    for (py::ssize_t q = 0; q < O * 3; ++q) {
        const float a = albedo.data()[q], e = emission.data()[q];
        if (!(a >= 0.0f && a <= 1.0f)) throw py::value_error("albedo values must lie in [0, 1]");
        if (!(e >= 0.0f) || !std::isfinite(e))
            throw py::value_error("emission values must be finite and >= 0");
    }
    if (threads < 0) throw py::value_error("threads must be >= 0 (0: all hardware threads)");

    voxgi::VoxelizeParams P;
    for (int d = 0; d < 3; ++d) {
        P.origin[d] = origin.data()[d];
        P.dims[d] = dims.data()[d];
    }
    P.pitch = pitch;
    P.cos_cluster = cos_cluster;
    P.cut = cut;
    P.eps = eps;
    const auto tex = make_textures(tex_texels, tex_info, obj_texture, corner_uv, F, O);
    if (tex) P.textures = &tex->surface;

    voxgi::VoxelizeStats st;
    voxgi::VoxelizeProgress prog;
    voxgi::StopCheck base = make_stop_check();
    voxgi::StopCheck stop = base;
    if (!progress.is_none()) {
        // Poll the progress callable from the calling thread only (where the
        // StopCheck runs), at most every 100 ms, with the GIL briefly held.
        auto last = std::make_shared<std::chrono::steady_clock::time_point>(
            std::chrono::steady_clock::now());
        stop = [base, last, &prog, progress]() -> bool {
            if (base()) return true;
            const auto now = std::chrono::steady_clock::now();
            if (now - *last < std::chrono::milliseconds(100)) return false;
            *last = now;
            py::gil_scoped_acquire gil;
            progress(prog.phase.load(), prog.done.load(), prog.total.load());
            return false;
        };
    }

    std::vector<voxgi::VoxelChunk> chunks;
    const double* tp = triangles.data();
    const int32_t* op = tri_object.data();
    const bool* tsp = two_sided.data();
    const float* ap = albedo.data();
    const float* ep = emission.data();
    {
        py::gil_scoped_release release;
        chunks = voxgi::voxelize(tp, F, op, int32_t(O), tsp, ap, ep, P, threads, stop, st, &prog);
    }
    // the final state, so that a caller always hears of the end, however short the work
    if (!progress.is_none()) progress(prog.phase.load(), prog.total.load(), prog.total.load());
    py::ssize_t N = 0, M = 0, NP = 0;
    for (const auto& c : chunks)
        N += py::ssize_t(c.records.size()), M += py::ssize_t(c.pieces.size()),
            NP += py::ssize_t(c.planes.size() / 4);
    I32 ijk({N, py::ssize_t(3)});
    F32 normal({N, py::ssize_t(3)});
    F32 area(N);
    F32 alb({N, py::ssize_t(3)});
    F32 emi({N, py::ssize_t(3)});
    F64 centroid({N, py::ssize_t(3)});
    I32 object(N);
    B8 back(N);
    py::array_t<int8_t, py::array::c_style> side(N);
    I32 piece_tri(M);
    I32 piece_rec({M, py::ssize_t(2)});
    py::array_t<uint32_t, py::array::c_style> piece_side(M);
    I64 piece_plane_first(M + 1);
    F64 piece_plane({NP, py::ssize_t(4)});
    {
        int32_t *pt = piece_tri.mutable_data(), *pr = piece_rec.mutable_data();
        uint32_t* psd = piece_side.mutable_data();
        int64_t* ppf = piece_plane_first.mutable_data();
        double* ppl = piece_plane.mutable_data();
        int64_t plane = 0;
        int32_t *pi = ijk.mutable_data(), *po = object.mutable_data();
        float *pn = normal.mutable_data(), *pa = area.mutable_data(), *pal = alb.mutable_data(),
              *pe = emi.mutable_data();
        double* pc = centroid.mutable_data();
        bool* pb = back.mutable_data();
        int8_t* ps = side.mutable_data();
        py::gil_scoped_release release;
        py::ssize_t r = 0, m = 0;
        for (auto& c : chunks) {
            // the pieces' records, from the chunk's indices to the output's
            const int32_t first = int32_t(r);
            const double* cp = c.planes.data();
            for (const auto& pc : c.pieces) {
                pt[m] = pc.tri;
                pr[2 * m] = first + pc.front;
                pr[2 * m + 1] = first + pc.back;
                psd[m] = pc.side;
                ppf[m] = plane;
                std::copy(cp, cp + 4 * pc.n_planes, ppl + 4 * plane);
                cp += 4 * pc.n_planes;
                plane += pc.n_planes;
                ++m;
            }
            std::vector<voxgi::SurfacePiece>().swap(c.pieces);
            std::vector<double>().swap(c.planes);
            for (const auto& rec : c.records) {
                for (int d = 0; d < 3; ++d) {
                    pi[3 * r + d] = rec.ijk[d];
                    pn[3 * r + d] = rec.normal[d];
                    pal[3 * r + d] = rec.albedo[d];
                    pe[3 * r + d] = rec.emission[d];
                    pc[3 * r + d] = rec.centroid[d];
                }
                pa[r] = rec.area;
                po[r] = rec.object;
                pb[r] = rec.back != 0;
                ps[r] = static_cast<int8_t>(rec.side);
                ++r;
            }
            std::vector<voxgi::VoxelRecord>().swap(c.records);  // free as we go: peak ~ one copy
        }
        ppf[M] = plane;
    }
    const int64_t out_bytes =
        int64_t(N) * (12 + 12 + 4 + 12 + 12 + 24 + 4 + 1 + 1) + int64_t(M) * 24 + int64_t(NP) * 32;
    py::dict stats(
        "triangles"_a = st.triangles, "skipped_degenerate"_a = st.skipped_degenerate,
        "pairs"_a = st.pairs, "cells"_a = st.cells, "records"_a = st.records,
        "back_records"_a = st.back_records, "two_sided_records"_a = st.two_sided_records,
        "touch_records"_a = st.touch_records, "clusters"_a = st.clusters,
        "cut_clusters"_a = st.cut_clusters, "cut_records"_a = st.cut_records,
        "cut_limit_hits"_a = st.cut_limit_hits, "cut_small_planes"_a = st.cut_small_planes,
        "layer_records"_a = st.layer_records, "polygon_overflows"_a = st.polygon_overflows,
        "peak_bytes"_a = std::max<int64_t>(
            st.peak_bytes, int64_t(N) * int64_t(sizeof(voxgi::VoxelRecord)) + out_bytes),
        "seconds_pairs"_a = st.seconds_pairs, "seconds_sort"_a = st.seconds_sort,
        "seconds_records"_a = st.seconds_records, "threads"_a = voxgi::resolve_threads(threads));
    return py::dict("ijk"_a = ijk, "normal"_a = normal, "area"_a = area, "albedo"_a = alb,
                    "emission"_a = emi, "centroid"_a = centroid, "object_id"_a = object,
                    "back"_a = back, "side"_a = side, "piece_triangle"_a = piece_tri,
                    "piece_record"_a = piece_rec, "piece_side"_a = piece_side,
                    "piece_plane_first"_a = piece_plane_first, "piece_plane"_a = piece_plane,
                    "stats"_a = stats);
}

}  // namespace

void bind_voxelize(py::module_& m) {
    m.def("voxelize", &voxelize_py, "triangles"_a.noconvert(), "tri_object"_a.noconvert(),
          "two_sided"_a.noconvert(), "albedo"_a.noconvert(), "emission"_a.noconvert(),
          "origin"_a.noconvert(), "pitch"_a, "dims"_a.noconvert(), "cos_cluster"_a = 0.5,
          "cut"_a = true, "eps"_a = 1e-9, "threads"_a = 0, "progress"_a = py::none(),
          "tex_texels"_a = py::none(), "tex_info"_a.noconvert() = py::none(),
          "obj_texture"_a.noconvert() = py::none(), "corner_uv"_a.noconvert() = py::none(),
          R"doc(Exact sparse supercover voxelization of triangles (low level; see voxgi.voxelize).

Parameters
----------
triangles : (F, 3, 3) float64
    World corner positions, C-contiguous.
tri_object : (F,) int32
    Object index of each triangle, in [0, O).
two_sided : (O,) bool
albedo, emission : (O, 3) float32
origin : (3,) float64
    World position of voxel (0, 0, 0)'s minimum corner.
pitch : float
    Voxel edge, scene units.
dims : (3,) int32
    Grid size; every vertex must lie within origin + pitch * [0, dims].
cos_cluster : float
    Pieces of one object in one voxel whose normals make an angle larger than
    acos(cos_cluster) with the cluster's first piece form separate records.
cut : bool
    Cut each cluster's pieces by the planes of the other clusters in the voxel.
eps : float
    Touching tolerance in voxel units.
threads : int
    0: all hardware threads. The output does not depend on it.
progress : callable(phase, done, total) or None
    Called from the calling thread about every 100 ms, and once at the end
    with done == total.
tex_texels, tex_info, obj_texture, corner_uv : optional, all or none
    The objects' textures (a list of (H, W, 3) uint8; (T, 12) float64:
    filter, wrap, raw, to_uv, factor; (O,) int32, -1: none; (F, 3, 2)
    float32): a textured object's records take the texture's mean over their
    own surface as their albedo.

Returns
-------
dict
    ``ijk`` (N, 3) int32, ``normal`` (N, 3) float32, ``area`` (N,) float32,
    ``albedo``/``emission`` (N, 3) float32, ``centroid`` (N, 3) float64,
    ``object_id`` (N,) int32, ``back`` (N,) bool, ``side`` (N,) int8,
    ``piece_triangle`` (M,) int32 and ``piece_record`` (M, 2) int32: for each
    (triangle, voxel) piece with area, the triangle and the records on its
    winding side and on the other (the voxel is theirs), once per record
    pair its parts went to; ``piece_plane_first`` (M + 1,) int64 and
    ``piece_plane`` (P, 4) float64: each entry's planes [first[m],
    first[m + 1]), n and off in voxel units (x = (world - origin) / pitch),
    those that split a piece (none for a piece whole in one pair), and
    ``piece_side`` (M,) uint32, bit k set where the entry's part lies on
    its k-th plane's positive side (n·x >= off); ``stats`` (dict of counts
    and seconds).)doc");
}
