// pybind11 bindings for the display's gather rays (vpl_shade.h).
#include <pybind11/stl.h>

#include <optional>

#include "bind_shade.h"
#include "bind_texture.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace voxgi::py_helpers {

voxgi::RecordGrid make_grid(const I64& rec_sorted_key, const I32& rec_cell_start,
                            const F32& rec_packed, const I64& grid_dims, const I64& grid_lo,
                            const F64& grid_origin, double pitch) {
    check_1d(rec_sorted_key, -1, "rec_sorted_key");
    const py::ssize_t N = rec_sorted_key.shape(0);
    constexpr py::ssize_t kRow = sizeof(voxgi::PackedRecord) / sizeof(float);
    check_2d(rec_packed, N, kRow, "rec_packed");
    check_1d(grid_dims, 3, "grid_dims");
    check_1d(grid_lo, 3, "grid_lo");
    check_1d(grid_origin, 3, "grid_origin");
    if (!(pitch > 0.0) || !std::isfinite(pitch)) throw py::value_error("pitch must be > 0");
    {
        const int64_t* sk = rec_sorted_key.data();
        for (py::ssize_t i = 1; i < N; ++i)
            if (sk[i] < sk[i - 1]) throw py::value_error("rec_sorted_key must be ascending");
    }
    voxgi::RecordGrid grid;
    grid.count = N;
    grid.sorted_key = rec_sorted_key.data();
    // float rows of the layout of PackedRecord (its object field an int32's bits)
    grid.rec = reinterpret_cast<const voxgi::PackedRecord*>(rec_packed.data());
    for (int a = 0; a < 3; ++a) {
        grid.dims[a] = grid_dims.data()[a];
        grid.lo[a] = grid_lo.data()[a];
        grid.origin[a] = grid_origin.data()[a];
        if (grid.dims[a] < 1) throw py::value_error("grid_dims must be >= 1");
    }
    grid.pitch = pitch;
    // Optional dense table of each voxel key's first sorted record.
    check_1d(rec_cell_start, -1, "rec_cell_start");
    if (rec_cell_start.shape(0) > 0) {
        const int64_t cells = grid.dims[0] * grid.dims[1] * grid.dims[2];
        if (rec_cell_start.shape(0) != cells + 1)
            throw py::value_error("rec_cell_start must have dims product + 1 entries");
        const int32_t* cs = rec_cell_start.data();
        if (cs[0] != 0 || cs[cells] != N) throw py::value_error("rec_cell_start: bad bounds");
        for (int64_t c = 0; c < cells; ++c)
            if (cs[c + 1] < cs[c]) throw py::value_error("rec_cell_start must be ascending");
        grid.cell_start = cs;
    } else {
        const int64_t* sk = rec_sorted_key.data();
        if (N > 0 && (sk[0] < 0 || sk[N - 1] >= grid.dims[0] * grid.dims[1] * grid.dims[2]))
            throw py::value_error("rec_sorted_key: key outside the grid");
    }
    return grid;
}

void attach_pieces(voxgi::RecordGrid& grid, const PieceArgs& pc) {
    const int given = int(pc.first.has_value()) + int(pc.key.has_value()) +
                      int(pc.record.has_value()) + int(pc.side.has_value()) +
                      int(pc.plane_first.has_value()) + int(pc.plane.has_value());
    if (given == 0) return;
    if (given != 6)
        throw py::value_error(
            "piece_first, piece_key, piece_record, piece_side, piece_plane_first and "
            "piece_plane go together");
    check_1d(*pc.first, -1, "piece_first");
    check_1d(*pc.key, -1, "piece_key");
    const py::ssize_t M = pc.key->shape(0), T = pc.first->shape(0) - 1;
    check_2d(*pc.record, M, 2, "piece_record");
    check_1d(*pc.side, M, "piece_side");
    check_1d(*pc.plane_first, M + 1, "piece_plane_first");
    check_2d(*pc.plane, -1, 4, "piece_plane");
    if (T < 0) throw py::value_error("piece_first must have at least one entry");
    auto ascending = [](const int64_t* a, py::ssize_t n, int64_t end, const char* name) {
        if (a[0] != 0 || a[n] != end) throw py::value_error(std::string(name) + ": bad bounds");
        for (py::ssize_t i = 0; i < n; ++i)
            if (a[i + 1] < a[i]) throw py::value_error(std::string(name) + " must be ascending");
    };
    ascending(pc.first->data(), T, M, "piece_first");
    const int64_t* pf = pc.plane_first->data();
    ascending(pf, M, pc.plane->shape(0), "piece_plane_first");
    const int64_t cells = grid.dims[0] * grid.dims[1] * grid.dims[2];
    const int64_t* key = pc.key->data();
    const int32_t* rec = pc.record->data();
    for (py::ssize_t e = 0; e < M; ++e) {
        if (key[e] < 0 || key[e] >= cells) throw py::value_error("piece_key: key outside the grid");
        for (int s = 0; s < 2; ++s)
            if (rec[2 * e + s] < 0 || rec[2 * e + s] >= grid.count)
                throw py::value_error("piece_record: record index out of range");
        if (pf[e + 1] - pf[e] > 32) throw py::value_error("piece_plane_first: over 32 planes");
    }
    const double* pl = pc.plane->data();
    for (py::ssize_t k = 0; k < 4 * pc.plane->shape(0); ++k)
        if (!std::isfinite(pl[k])) throw py::value_error("piece_plane: not finite");
    grid.piece_tris = T;
    grid.piece_first = pc.first->data();
    grid.piece_key = key;
    grid.piece_record = rec;
    grid.piece_side = pc.side->data();
    grid.piece_plane_first = pf;
    grid.piece_plane = pl;
}

}  // namespace voxgi::py_helpers

namespace {

voxgi::ShadeTriangles make_triangles(const F64& tri_v, const I32& tri_object,
                                     const U8& obj_two_sided) {
    if (tri_v.ndim() != 3 || tri_v.shape(1) != 3 || tri_v.shape(2) != 3)
        throw py::value_error("tri_v must have shape (F, 3, 3)");
    const py::ssize_t F = tri_v.shape(0);
    check_1d(tri_object, F, "tri_object");
    check_1d(obj_two_sided, -1, "obj_two_sided");
    const py::ssize_t O = obj_two_sided.shape(0);
    {
        const int32_t* to = tri_object.data();
        for (py::ssize_t f = 0; f < F; ++f)
            if (to[f] < 0 || to[f] >= O) throw py::value_error("tri_object: index out of range");
    }
    voxgi::ShadeTriangles tris;
    tris.count = F;
    tris.v = tri_v.data();
    tris.object = tri_object.data();
    tris.two_sided = obj_two_sided.data();
    return tris;
}

// The frame's emitter VPLs, sampled where a ray continues (ShadeTriangles),
// into tris; all four arrays or none. tris.emits must be set already.
void attach_emitters(voxgi::ShadeTriangles& tris, const std::optional<F64>& emitter_pos,
                     const std::optional<F32>& emitter_normal,
                     const std::optional<F32>& emitter_radiance,
                     const std::optional<F32>& emitter_density, double emitter_per_set) {
    const int given = int(emitter_pos.has_value()) + int(emitter_normal.has_value()) +
                      int(emitter_radiance.has_value()) + int(emitter_density.has_value());
    if (given != 0 && given != 4)
        throw py::value_error("emitter_pos, _normal, _radiance and _density go together");
    if (given == 0) return;
    // (without the emitters marked, a bounce landing on one would count it
    // again beside its VPL sample)
    if (!tris.emits) throw py::value_error("emitter_pos needs obj_emits");
    check_2d(*emitter_pos, -1, 3, "emitter_pos");
    const py::ssize_t K = emitter_pos->shape(0);
    check_2d(*emitter_normal, K, 3, "emitter_normal");
    check_2d(*emitter_radiance, K, 3, "emitter_radiance");
    check_1d(*emitter_density, K, "emitter_density");
    tris.emitter_count = K;
    tris.emitter_pos = emitter_pos->data();
    tris.emitter_normal = emitter_normal->data();
    tris.emitter_radiance = emitter_radiance->data();
    tris.emitter_density = emitter_density->data();
    if (!(emitter_per_set >= 1.0) || !std::isfinite(emitter_per_set))
        throw py::value_error("emitter_per_set must be >= 1");
    tris.emitter_per_set = emitter_per_set;
}

// rec_stacked into grid and, with pieces_for_sheets, the objects that hold
// a stacked record (into `objects`, which must outlive the grid's use).
void attach_stacked(voxgi::RecordGrid& grid, const std::optional<U8>& rec_stacked,
                    bool pieces_for_sheets, std::vector<uint8_t>& objects) {
    if (rec_stacked) {
        check_1d(*rec_stacked, grid.count, "rec_stacked");
        grid.stacked = rec_stacked->data();
    }
    if (pieces_for_sheets && !(rec_stacked && grid.piece_first))
        throw py::value_error("pieces_for_sheets needs rec_stacked and the piece_* tables");
    grid.pieces_for_sheets = pieces_for_sheets;
    if (!pieces_for_sheets) return;
    for (int64_t r = 0; r < grid.count; ++r) {
        if (!grid.stacked[r]) continue;
        const int32_t obj = grid.rec[r].object;
        if (obj < 0) continue;
        if (size_t(obj) >= objects.size()) objects.resize(size_t(obj) + 1, 0);
        objects[size_t(obj)] = 1;
    }
    grid.stacked_objects = objects.data();
    grid.stacked_object_count = int64_t(objects.size());
}

int64_t gather_light_py(
    F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material, F32 mat_albedo,
    F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy, int n_gather, uint64_t seed, int64_t frame,
    double eps, F64 tri_v, I32 tri_object, U8 obj_two_sided, I64 rec_sorted_key, I32 rec_cell_start,
    F32 rec_packed, I64 grid_dims, I64 grid_lo, F64 grid_origin, double pitch,
    const voxgi::RayScene& scene, F32Out out, int threads, const std::optional<F64>& env_radiance,
    const std::optional<F64>& env_to_world, const std::optional<F64>& env_texel_pdf,
    const std::optional<F64>& env_row_solid_angle, double env_samples,
    const std::optional<F32>& hit_albedo, const std::optional<std::vector<U8>>& tex_texels,
    const std::optional<F64>& tex_info, const std::optional<I32>& obj_texture,
    const std::optional<F32>& corner_uv, const std::optional<F32>& mat_lobe,
    std::optional<I32Out> transport_record, std::optional<F32Out> transport_weight,
    const std::optional<F32>& mat_response, const std::optional<U8>& mat_continue,
    const std::optional<F32>& rec_share, const voxgi::EnvironmentGuide* env_guide,
    const std::optional<F32>& mat_base_out, const std::optional<U8>& obj_emits, double reach,
    const std::optional<F64>& emitter_pos, const std::optional<F32>& emitter_normal,
    const std::optional<F32>& emitter_radiance, const std::optional<F32>& emitter_density,
    double emitter_per_set, const std::optional<I64>& piece_first,
    const std::optional<I64>& piece_key, const std::optional<I32>& piece_record,
    const std::optional<U32>& piece_side, const std::optional<I64>& piece_plane_first,
    const std::optional<F64>& piece_plane, const std::optional<F32>& obj_lobe,
    const std::optional<F32>& rec_emitted, std::optional<F32Out> emitted_out,
    const std::optional<U8>& rec_stacked, bool pieces_for_sheets) {
    voxgi::ShadeMaterials mats =
        materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy, mat_lobe);
    if (mat_response) {
        if (check_incidence_table(*mat_response, "mat_response") != mats.count)
            throw py::value_error("mat_response: one row per material");
        mats.response = mat_response->data();
    }
    if (mat_continue.has_value() != rec_share.has_value())
        throw py::value_error("mat_continue and rec_share go together");
    if (obj_lobe) {
        // the records as pixels: their rays land on the scene's objects
        mats.hit_lobe = lobe_rows(*obj_lobe, obj_two_sided.shape(0), "obj_lobe");
        mats.hit_count = obj_lobe->shape(0);
    }
    if (mat_continue) {
        if (!mats.hit_lobe) throw py::value_error("mat_continue needs mat_lobe or obj_lobe");
        check_1d(*mat_continue, mats.hit_count, "mat_continue");
        mats.continue_lobe = mat_continue->data();
    }
    if (mat_base_out) {
        if (!mat_continue) throw py::value_error("mat_base_out needs mat_continue");
        if (check_incidence_table(*mat_base_out, "mat_base_out") != mats.count)
            throw py::value_error("mat_base_out: one row per material");
        mats.base_out = mat_base_out->data();
    }
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    set_hit_albedo(hits, hit_albedo);
    if (n_gather < 1 || n_gather > 4096) throw py::value_error("n_gather must be in [1, 4096]");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::ShadeMIS mis = make_mis(n_gather);
    voxgi::ShadeTriangles tris = make_triangles(tri_v, tri_object, obj_two_sided);
    check_scene(scene, tris.count);
    if (obj_emits) {
        check_1d(*obj_emits, obj_two_sided.shape(0), "obj_emits");
        tris.emits = obj_emits->data();
    }
    if (!(reach >= 0.0) || !std::isfinite(reach))
        throw py::value_error("reach must be finite and >= 0");
    if (reach > 0.0 && !obj_emits) throw py::value_error("reach needs obj_emits");
    tris.reach = reach;
    attach_emitters(tris, emitter_pos, emitter_normal, emitter_radiance, emitter_density,
                    emitter_per_set);
    const auto tex = make_textures(tex_texels, tex_info, obj_texture, corner_uv, tris.count,
                                   obj_two_sided.shape(0));
    if (tex) tris.textures = &tex->surface;
    voxgi::RecordGrid grid = make_grid(rec_sorted_key, rec_cell_start, rec_packed, grid_dims,
                                       grid_lo, grid_origin, pitch);
    attach_pieces(
        grid, {piece_first, piece_key, piece_record, piece_side, piece_plane_first, piece_plane});
    if (rec_share) {
        check_2d(*rec_share, grid.count, 3, "rec_share");
        grid.share = rec_share->data();
    }
    std::optional<voxgi::EnvironmentMap> env = make_environment(
        env_radiance, env_to_world, env_texel_pdf, env_row_solid_angle, env_samples);
    if (env_guide && !env) throw py::value_error("env_guide needs the environment's tables");
    if (env) attach_guide(*env, env_guide);
    check_2d(out, hits.count, 3, "out");
    check_inplace(out, "out");
    float* po = out.mutable_data();
    voxgi::GatherTransport transport;
    if (transport_record.has_value() != transport_weight.has_value())
        throw py::value_error("transport_record and transport_weight go together");
    if (transport_record) {
        check_1d(*transport_record, hits.count * n_gather, "transport_record");
        check_2d(*transport_weight, hits.count * n_gather, 3, "transport_weight");
        check_inplace(*transport_record, "transport_record");
        check_inplace(*transport_weight, "transport_weight");
        transport.record = transport_record->mutable_data();
        transport.weight = transport_weight->mutable_data();
    }
    if (transport_record && mat_continue) {
        // the transport keeps one record a ray: the lobe's, none of the base's share
        for (int64_t r = 0; r < grid.count; ++r) {
            const int32_t obj = grid.rec[r].object;
            if (obj < 0 || obj >= mats.hit_count || !mats.continue_lobe[obj]) continue;
            for (int ch = 0; ch < 3; ++ch)
                if (grid.share[3 * r + ch] != 0.f)
                    throw py::value_error(
                        "rec_share: record " + std::to_string(r) + " of object " +
                        std::to_string(obj) +
                        " continues its lobe with a base share; the transport keeps none");
        }
    }
    std::vector<uint8_t> stacked_objects;
    attach_stacked(grid, rec_stacked, pieces_for_sheets, stacked_objects);
    voxgi::LobeEmission lobe_emission;
    if (rec_emitted.has_value() != emitted_out.has_value())
        throw py::value_error("rec_emitted and emitted_out go together");
    if (rec_emitted) {
        check_2d(*rec_emitted, grid.count, 3, "rec_emitted");
        check_2d(*emitted_out, hits.count, 3, "emitted_out");
        check_inplace(*emitted_out, "emitted_out");
        lobe_emission.radiance = rec_emitted->data();
        lobe_emission.out = emitted_out->mutable_data();
    }
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::gather_light(hits, mats, mis, n_gather, seed, frame, eps, tris, grid,
                            env ? &*env : nullptr, scene, po, &rays, threads, stop,
                            transport_record ? &transport : nullptr,
                            rec_emitted ? &lobe_emission : nullptr);
    }
    return rays;
}

py::array_t<float> sheet_radiance_py(
    F64 point_pos, F32 point_normal, I64 point_record, int walks, uint64_t seed, int64_t frame,
    double eps, F64 tri_v, I32 tri_object, U8 obj_two_sided, U8 obj_emits, I64 rec_sorted_key,
    I32 rec_cell_start, F32 rec_packed, I64 grid_dims, I64 grid_lo, F64 grid_origin, double pitch,
    U8 rec_stacked, const voxgi::RayScene& scene, int threads,
    const std::optional<F64>& emitter_pos, const std::optional<F32>& emitter_normal,
    const std::optional<F32>& emitter_radiance, const std::optional<F32>& emitter_density,
    double emitter_per_set, const std::optional<I64>& piece_first,
    const std::optional<I64>& piece_key, const std::optional<I32>& piece_record,
    const std::optional<U32>& piece_side, const std::optional<I64>& piece_plane_first,
    const std::optional<F64>& piece_plane, bool pieces_for_sheets) {
    if (walks < 1 || walks > 4096) throw py::value_error("walks must be in [1, 4096]");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::ShadeTriangles tris = make_triangles(tri_v, tri_object, obj_two_sided);
    check_scene(scene, tris.count);
    check_1d(obj_emits, obj_two_sided.shape(0), "obj_emits");
    tris.emits = obj_emits.data();
    attach_emitters(tris, emitter_pos, emitter_normal, emitter_radiance, emitter_density,
                    emitter_per_set);
    voxgi::RecordGrid grid = make_grid(rec_sorted_key, rec_cell_start, rec_packed, grid_dims,
                                       grid_lo, grid_origin, pitch);
    attach_pieces(
        grid, {piece_first, piece_key, piece_record, piece_side, piece_plane_first, piece_plane});
    std::vector<uint8_t> stacked_objects;
    attach_stacked(grid, rec_stacked, pieces_for_sheets, stacked_objects);
    check_2d(point_pos, -1, 3, "point_pos");
    const py::ssize_t K = point_pos.shape(0);
    check_2d(point_normal, K, 3, "point_normal");
    check_1d(point_record, K, "point_record");
    voxgi::SheetPoints at;
    at.count = K;
    at.pos = point_pos.data();
    at.normal = point_normal.data();
    at.record = point_record.data();
    for (py::ssize_t i = 0; i < K; ++i) {
        const int64_t r = at.record[i];
        if (r < 0 || r >= grid.count)
            throw py::value_error("point_record: record " + std::to_string(r) + " out of range");
        if (grid.stacked[r] != 1)
            throw py::value_error("point_record: record " + std::to_string(r) +
                                  " is not a stacked sheet that walks on (rec_stacked 1)");
        for (int a = 0; a < 3; ++a)
            if (!std::isfinite(at.pos[3 * i + a]) || !std::isfinite(at.normal[3 * i + a]))
                throw py::value_error("point_pos, point_normal: not finite at point " +
                                      std::to_string(i));
    }
    py::array_t<float> out({K, py::ssize_t(3)});
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::sheet_radiance(tris, grid, scene, eps, at, walks, seed, frame, out.mutable_data(),
                              &rays, threads, stop);
    }
    return out;
}

}  // namespace

void bind_gather_light(py::module_& m) {
    m.def("sheet_radiance", &sheet_radiance_py, "point_pos"_a.noconvert(),
          "point_normal"_a.noconvert(), "point_record"_a.noconvert(), "walks"_a, "seed"_a,
          "frame"_a, "eps"_a, "tri_v"_a.noconvert(), "tri_object"_a.noconvert(),
          "obj_two_sided"_a.noconvert(), "obj_emits"_a.noconvert(), "rec_sorted_key"_a.noconvert(),
          "rec_cell_start"_a.noconvert(), "rec_packed"_a.noconvert(), "grid_dims"_a.noconvert(),
          "grid_lo"_a.noconvert(), "grid_origin"_a.noconvert(), "pitch"_a,
          "rec_stacked"_a.noconvert(), "scene"_a, "threads"_a = 0,
          "emitter_pos"_a.noconvert() = py::none(), "emitter_normal"_a.noconvert() = py::none(),
          "emitter_radiance"_a.noconvert() = py::none(),
          "emitter_density"_a.noconvert() = py::none(), "emitter_per_set"_a = 1.0,
          "piece_first"_a.noconvert() = py::none(), "piece_key"_a.noconvert() = py::none(),
          "piece_record"_a.noconvert() = py::none(), "piece_side"_a.noconvert() = py::none(),
          "piece_plane_first"_a.noconvert() = py::none(), "piece_plane"_a.noconvert() = py::none(),
          "pieces_for_sheets"_a = false,
          R"doc(The radiance leaving points on stacked sheets (K, 3) float32: per point
(point_pos (K, 3) float64 in the grid's frame, point_normal (K, 3) float32,
point_record (K,) int64, a record marked 1 in rec_stacked), the mean of
`walks` walks through its stack as gather_light's rays walk on from a sheet
they land on, seeded by (seed, frame, point, walk); with the frame's emitter
VPLs (emitter_*, as gather_light takes them) the emitters' light is sampled
at every bounce. The other arguments as gather_light's.)doc");
    m.def(
        "gather_light", &gather_light_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
        "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
        "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
        "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "n_gather"_a, "seed"_a, "frame"_a,
        "eps"_a, "tri_v"_a.noconvert(), "tri_object"_a.noconvert(), "obj_two_sided"_a.noconvert(),
        "rec_sorted_key"_a.noconvert(), "rec_cell_start"_a.noconvert(), "rec_packed"_a.noconvert(),
        "grid_dims"_a.noconvert(), "grid_lo"_a.noconvert(), "grid_origin"_a.noconvert(), "pitch"_a,
        "scene"_a, "out"_a.noconvert(), "threads"_a = 0, "env_radiance"_a.noconvert() = py::none(),
        "env_to_world"_a.noconvert() = py::none(), "env_texel_pdf"_a.noconvert() = py::none(),
        "env_row_solid_angle"_a.noconvert() = py::none(), "env_samples"_a = 0.0,
        "hit_albedo"_a.noconvert() = py::none(), "tex_texels"_a = py::none(),
        "tex_info"_a.noconvert() = py::none(), "obj_texture"_a.noconvert() = py::none(),
        "corner_uv"_a.noconvert() = py::none(), "mat_lobe"_a.noconvert() = py::none(),
        "transport_record"_a.noconvert() = py::none(),
        "transport_weight"_a.noconvert() = py::none(), "mat_response"_a.noconvert() = py::none(),
        "mat_continue"_a.noconvert() = py::none(), "rec_share"_a.noconvert() = py::none(),
        "env_guide"_a = py::none(), "mat_base_out"_a.noconvert() = py::none(),
        "obj_emits"_a.noconvert() = py::none(), "reach"_a = 0.0,
        "emitter_pos"_a.noconvert() = py::none(), "emitter_normal"_a.noconvert() = py::none(),
        "emitter_radiance"_a.noconvert() = py::none(), "emitter_density"_a.noconvert() = py::none(),
        "emitter_per_set"_a = 1.0, "piece_first"_a.noconvert() = py::none(),
        "piece_key"_a.noconvert() = py::none(), "piece_record"_a.noconvert() = py::none(),
        "piece_side"_a.noconvert() = py::none(), "piece_plane_first"_a.noconvert() = py::none(),
        "piece_plane"_a.noconvert() = py::none(), "obj_lobe"_a.noconvert() = py::none(),
        "rec_emitted"_a.noconvert() = py::none(), "emitted_out"_a.noconvert() = py::none(),
        "rec_stacked"_a.noconvert() = py::none(), "pieces_for_sheets"_a = false,
        R"doc(Cosine-distributed gather rays (n_gather per shaded pixel, stratified,
hashed from seed/frame/pixel), traced in scene (a RayScene built from tri_v)
as they are made, each shaded with the radiance of the record at its hit
point (rec_*, grid_*, pitch: voxgi.traced.record_grid), MIS-weighted against
the VPLs; added into out (P, 3) float32. With the environment's tables
(env_radiance (H, W, 3) float64, env_to_world (3, 3), env_texel_pdf (H*W,),
env_row_solid_angle (H,) float64, as voxgi.Environment samples), a ray that
meets nothing adds the environment's radiance MIS-weighted against
env_samples environment samples per pixel (drawn by env_guide, an
EnvironmentGuide, where given). With hit_albedo (P, 3) float32
each pixel's own diffuse albedo replaces its material's; with the textures
(as camera_hits takes them) a ray that lands on a textured object takes the
record's radiance times the texture there over the record's albedo (the
packed row's albedo). With transport_record (P * n_gather,) int32 and
transport_weight (P * n_gather, 3) float32, ray k of shaded pixel p writes at
p * n_gather + k the record it read (position in rec_packed, -1: none) and
the factor the record's radiance was multiplied by (transport_compact).
With mat_response (M, 33, 3) float32 (the solve's records as pixels), a
ray's f is multiplied by its material's row of R / A at the ray's cosine
(voxgi.incidence). With mat_continue (M,) uint8 and mat_lobe, a ray that
lands on a material marked 1 reads its record's base share and follows the
lobe's specular reflection one bounce further, reading rec_share (N, 3)
float32 (in rec_packed's order, given with mat_continue) of its record's
light; with mat_base_out (M, 33, 3) float32 that share times the hit
material's row at the cosine towards the ray's origin (the base's outgoing
radiance over its mean). mat_continue and the lobes rays land on are per
object: the materials' own rows (mat_lobe), or obj_lobe (O, LOBE_WIDTH)
float32 where the pixels' materials are not the objects (the solve's
records). With the transport, such a ray is written as the record at the
end of the lobe's ray; the transport keeps no base share, so every record
of a continuing object must have a zero rec_share. With rec_emitted (N, 3)
float32 (each record's emitted radiance, rec_packed's order) and
emitted_out (P, 3) float32, a ray that follows a lobe also adds the light
it reads of the emitter where the lobe's ray lands into emitted_out.
With rec_stacked (N,) uint8 (rec_packed's order), a ray that lands on a
record marked 1 or 2 (a sheet of a stack finer than a voxel; 2: one that
emits) reads, instead of the record, its albedo times the record where one
cosine-distributed ray from the landing point lands, as a lobe's ray is
read (the transport and emitted_out alike); where that ray lands on a
record marked 1 it bounces on in the same way, up to 8 bounces in all;
given the emitter VPLs (below), each bounce also draws one of them with a
shadow ray, MIS-combined with the bounce that lands on an emitter.
With the piece_* tables a ray reads the record of the piece of the
triangle it lands on; with pieces_for_sheets only to tell whether that is
a stacked sheet and to walk the stack, every other lookup searching.
With reach > 0 and obj_emits (O,) uint8 (1: the object emits), a ray that
lands nearer than reach to its pixel's point on a diffuse object that does
not emit continues one bounce: its albedo times one cosine-distributed ray
from there (the record where it lands, or the environment) and, given the
frame's emitter VPLs (emitter_pos (K, 3) float64, emitter_normal (K, 3),
emitter_radiance (K, 3) B / pi and emitter_density (K,) their records' area
density p(y), float32; emitter_per_set the emitter VPLs a pixel sees, by
which a record's packed pa is divided for p(y)), one of them drawn
uniformly with a shadow ray, the two MIS-combined (balance heuristic).
With the piece table (piece_first (T + 1,) int64, piece_key (M,) int64,
piece_record (M, 2) int32, piece_side (M,) uint32, piece_plane_first
(M + 1,) int64, piece_plane (P, 4) float64; voxgi.traced's), a ray that
lands on a triangle below T in a voxel where that triangle's piece is
listed reads, without searching the voxel, the record on the side it meets
of the piece's part that holds the landing point.
Returns the number of gather rays.)doc");
}
