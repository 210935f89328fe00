// pybind11 bindings of the reference and adjoint variants (reference.cpp),
// in the private submodule voxgi._core.testing: for the tests only.
#include "bind_lines.h"
#include "bind_shade.h"

// The record lookup as first written (each candidate in visiting order,
// each one's separation asking every other record of the voxel afresh),
// kept here only to check the kernels' lookup against: the same record for
// every hit.
namespace voxgi::lookup_reference {
namespace {

inline float dot3(const float* a, const float* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// The records of voxel (i, j, k): [q0, q1) in the grid's order (empty outside it).
inline void cell_records(const RecordGrid& g, int64_t i, int64_t j, int64_t k, int64_t& q0,
                         int64_t& q1) {
    q0 = q1 = 0;
    const int64_t key = grid_key(g, i, j, k);
    if (key < 0) return;
    if (g.cell_start) {
        q0 = g.cell_start[key], q1 = g.cell_start[key + 1];
    } else {
        q0 = std::lower_bound(g.sorted_key, g.sorted_key + g.count, key) - g.sorted_key;
        q1 = std::upper_bound(g.sorted_key + q0, g.sorted_key + g.count, key) - g.sorted_key;
    }
}

// How far record r stands apart from the hit point y (on a surface seen from
// the side of normal n) by the records [q0, q1) of a voxel: 2 when
// - it lies off the hit's own sheet: some record o whose plane holds y,
//   facing n's side, has r's centroid strictly in front of or behind it
//   (the other face of a slab thinner than a voxel, or its black back),
//   unless r is of o's object and orientation and another plane of the
//   voxel sets o apart from y (a sliver of the hit's face beyond another
//   surface);
// - or across another surface: some record o of another object, or of an
//   orientation more than 60° away (another cluster of the voxelization),
//   has y strictly on one side of its plane and r's centroid not on that
//   side. Those are the planes junction cutting split r's surface by, so
//   this keeps a hit on one side of a thin wall from reading the record on
//   the other;
// 1 when it is apart only by the signs of y's distances within rounding of
// such a plane (the best guess there); 0 otherwise.
// Record o's plane at y: y's signed distance to it, r's centroid's, and
// whether it holds y facing n's side (within rounding of its float centroid:
// a few units in the last place of its coordinates).
struct Side {
    double tol, sy, sr, behind;
    bool holds;
};
Side side_of(const RecordGrid& g, const PackedRecord& o, const double y[3], const float n[3],
             const PackedRecord& r) {
    Side s{1e-6 * g.pitch + 3e-7 * std::max({std::fabs(o.centroid[0]), std::fabs(o.centroid[1]),
                                             std::fabs(o.centroid[2])}),
           0.0, 0.0, 0.0, false};
    for (int a = 0; a < 3; ++a) {
        const double rc = double(r.centroid[a]) - o.centroid[a];
        s.sy += (y[a] - o.centroid[a]) * o.normal[a];
        s.sr += rc * o.normal[a];
        s.behind += rc * n[a];
    }
    s.holds = std::fabs(s.sy) <= s.tol && dot3(o.normal, n) > 0.5f;
    return s;
}

// r apart from y across o's plane: 2, 1 or 0 (the second rule below).
int across(const PackedRecord& o, const Side& s, const PackedRecord& r) {
    const float along = dot3(o.normal, r.normal);
    // r's own sheet: its orientation, or its other side through r's
    // centroid (a curved sheet's y lies off that plane on either side).
    if (o.object == r.object && (along > 0.5f || (along < -0.5f && std::fabs(s.sr) <= s.tol)))
        return 0;
    // A centroid on that plane (a sliver cut off at a junction) is on
    // neither side: it does not stand for a point off the plane.
    if ((s.sy > s.tol && s.sr < s.tol) || (s.sy < -s.tol && s.sr > -s.tol)) return 2;
    return (s.sy > 0.0 && s.sr < 0.0) || (s.sy < 0.0 && s.sr > 0.0) ? 1 : 0;
}

int separation(const RecordGrid& g, const double y[3], const float n[3], const PackedRecord& r,
               int64_t q0, int64_t q1) {
    int level = 0;
    for (int64_t q = q0; q < q1; ++q) {
        const PackedRecord& o = g.rec[q];
        if (&o == &r) continue;
        const Side s = side_of(g, o, y, n, r);
        if (s.holds) {
            if (!(std::fabs(s.behind) > s.tol)) continue;
            // a sliver of the hit's face across another surface from y does
            // not set its own surface's neighbouring clusters apart
            bool cut = false;
            if (o.object == r.object && dot3(o.normal, r.normal) > 0.5f)
                for (int64_t k = q0; k < q1 && !cut; ++k) {
                    if (k == q) continue;
                    const Side t = side_of(g, g.rec[k], y, n, o);
                    cut = !t.holds && across(g.rec[k], t, o) == 2;
                }
            if (cut) continue;
            return 2;
        }
        const int apart = across(o, s, r);
        if (apart == 2) return 2;
        level = std::max(level, apart);
    }
    return level;
}

// Position in the grid's order of the record that stands for the surface
// point y, in voxel c, on object `obj` seen from the side of normal n, or
// -1. Only records whose normal faces n's side qualify, and of those the
// ones no other surface of y's voxel (or of their own) separates from y;
// among them the nearest centroid, strongly preferring the same object and
// orientation. The neighbouring voxels within reach of y are searched only
// when c has no such record of this surface.
int64_t lookup_in_cell(const RecordGrid& g, const double y[3], const float n[3], int32_t obj,
                       const int64_t c[3]) {
    const double p2 = g.pitch * g.pitch;
    int64_t best = -1, h0, h1;
    int best_apart = 0;
    double best_score = 0.0, best_penalty = 0.0;
    cell_records(g, c[0], c[1], c[2], h0, h1);
    auto scan = [&](int64_t i, int64_t j, int64_t k, bool own) {
        int64_t q0, q1;
        cell_records(g, i, j, k, q0, q1);
        for (int64_t q = q0; q < q1; ++q) {
            const PackedRecord& r = g.rec[q];
            const float facing = dot3(r.normal, n);
            if (!(facing > 0.f)) continue;  // the other side of a sheet, or of a fold
            const double dx = y[0] - r.centroid[0], dy = y[1] - r.centroid[1],
                         dz = y[2] - r.centroid[2];
            const double penalty = 4.0 * (1.0 - facing) + (r.object != obj ? 4.0 : 0.0);
            const double score = dx * dx + dy * dy + dz * dz + p2 * penalty;
            if (best >= 0 && best_apart == 0 && score >= best_score) continue;
            int apart = separation(g, y, n, r, h0, h1);
            if (!own && apart < 2) apart = std::max(apart, separation(g, y, n, r, q0, q1));
            if (best < 0 || apart < best_apart || (apart == best_apart && score < best_score))
                best = q, best_score = score, best_penalty = penalty, best_apart = apart;
        }
    };
    scan(c[0], c[1], c[2], true);
    if (best >= 0 && best_penalty < 0.5 && best_apart == 0) return best;
    for (int di = -1; di <= 1; ++di)
        for (int dj = -1; dj <= 1; ++dj)
            for (int dk = -1; dk <= 1; ++dk)
                if ((di || dj || dk) && neighbour_within_reach(g, y, c, di, dj, dk))
                    scan(c[0] + di, c[1] + dj, c[2] + dk, false);
    return best;
}

}  // namespace
}  // namespace voxgi::lookup_reference

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

py::tuple gather_sorted(const voxgi::LineSystem& s, I32 families, F64 weights, F32 values,
                        I64 family_indices, bool want_vis, int threads,
                        std::optional<Bool> stand_in, bool transpose) {
    auto fams = to_families(families, weights);
    const py::ssize_t n = s.size();
    check_2d(values, n, 3, "values");
    check_selection(family_indices, fams.size());
    GatherArrays out(n, want_vis);
    const uint8_t* sb = flags_ptr(stand_in, n, "stand_in");
    const float* v = values.data();
    const int64_t* sel = family_indices.data();
    const py::ssize_t ns = family_indices.shape(0);
    double *o = out.sums.mutable_data(), *vp = out.vis_ptr();
    auto stop = make_stop_check();
    int64_t lines;
    {
        py::gil_scoped_release release;
        voxgi::GatherOptions opt;
        opt.stand_in = sb;
        opt.threads = threads;
        lines = voxgi::gather_sorted(s, fams.data(), sel, ns, v, o, vp, transpose, opt, stop);
    }
    return py::make_tuple(out.sums, out.vis_or_none(), lines);
}

py::tuple shoot_sender_side(const voxgi::LineSystem& s, I32 emitters, I32 families, F64 weights,
                            F32 values, F64 send_scale, F64 recv_area, int threads,
                            std::optional<Bool> stand_in) {
    auto fams = to_families(families, weights);
    const py::ssize_t n = s.size();
    check_1d(emitters, -1, "emitters");
    check_2d(values, n, 3, "values");
    check_1d(send_scale, n, "send_scale");
    check_1d(recv_area, n, "recv_area");
    const py::ssize_t ne = emitters.shape(0);
    F64 hd({n, py::ssize_t(3)});
    F64 unfound(ne);
    const int32_t* e = emitters.data();
    const float* v = values.data();
    const double *ss = send_scale.data(), *ra = recv_area.data();
    const uint8_t* sb = flags_ptr(stand_in, n, "stand_in");
    double *h = hd.mutable_data(), *u = unfound.mutable_data();
    auto stop = make_stop_check();
    voxgi::ShootCount count;
    {
        py::gil_scoped_release release;
        voxgi::ShootOptions opt;
        opt.stand_in = sb;
        opt.threads = threads;
        count = voxgi::shoot_sender_side(s, e, ne, fams.data(), static_cast<int64_t>(fams.size()),
                                         v, ss, ra, h, u, opt, stop);
    }
    return py::make_tuple(hd, unfound, count.rays, count.steps);
}

// Whether each array reaches the kernels aligned for its element type (the
// input aliases of bind_common.h promise it, whatever the caller passes).
py::tuple input_alignment(I32 i32, I64 i64, F32 f32, F64 f64) {
    auto aligned = [](const void* p, size_t a) { return reinterpret_cast<uintptr_t>(p) % a == 0; };
    return py::make_tuple(
        aligned(i32.data(), alignof(int32_t)), aligned(i64.data(), alignof(int64_t)),
        aligned(f32.data(), alignof(float)), aligned(f64.data(), alignof(double)));
}

// The record each hit (y (H, 3) float64 in the tracer's frame, n (H, 3)
// unit float32 normals on the side seen, obj (H,)) reads on the grid of
// voxgi.traced.record_grid, by the kernels' lookup or by the reference one:
// (H,) int64 rows of rec_packed, -1 for none.
I64 record_lookup(I64 rec_sorted_key, I32 rec_cell_start, F32 rec_packed, I64 grid_dims,
                  I64 grid_lo, F64 grid_origin, double pitch, F64 y, F32 n, I32 obj, bool reference,
                  const std::optional<I32>& tri, const std::optional<U8>& front,
                  const std::optional<I64>& piece_first, const std::optional<I64>& piece_key,
                  const std::optional<I32>& piece_record, const std::optional<U32>& piece_side,
                  const std::optional<I64>& piece_plane_first,
                  const std::optional<F64>& piece_plane) {
    voxgi::RecordGrid g = make_grid(rec_sorted_key, rec_cell_start, rec_packed, grid_dims, grid_lo,
                                    grid_origin, pitch);
    attach_pieces(
        g, {piece_first, piece_key, piece_record, piece_side, piece_plane_first, piece_plane});
    check_2d(y, -1, 3, "y");
    const py::ssize_t H = y.shape(0);
    check_2d(n, H, 3, "n");
    check_1d(obj, H, "obj");
    if (tri.has_value() != front.has_value()) throw py::value_error("tri and front go together");
    if (tri) check_1d(*tri, H, "tri"), check_1d(*front, H, "front");
    const int32_t* pt = tri ? tri->data() : nullptr;
    const uint8_t* pf = front ? front->data() : nullptr;
    I64 out(H);
    const double* yp = y.data();
    const float* pn = n.data();
    const int32_t* po = obj.data();
    int64_t* res = out.mutable_data();
    {
        py::gil_scoped_release release;
        voxgi::LookupScratch scratch;
        for (py::ssize_t h = 0; h < H; ++h) {
            int64_t c[3];
            voxgi::cell_of(g, yp + 3 * h, c);
            res[h] =
                reference
                    ? voxgi::lookup_reference::lookup_in_cell(g, yp + 3 * h, pn + 3 * h, po[h], c)
                    : voxgi::lookup_in_cell(g, yp + 3 * h, pn + 3 * h, po[h], c, pt ? pt[h] : -1,
                                            pf ? pf[h] != 0 : true, scratch);
        }
    }
    return out;
}

}  // namespace

void bind_testing(py::module_& m) {
    py::module_ t = m.def_submodule(
        "testing", "Reference and adjoint variants of the kernels, for the tests only.");
    t.def("gather_sorted", &gather_sorted, "system"_a, "families"_a.noconvert(),
          "weights"_a.noconvert(), "values"_a.noconvert(), "family_indices"_a.noconvert(),
          "want_vis"_a = false, "threads"_a = 0, "stand_in"_a.noconvert() = py::none(),
          "transpose"_a = false,
          R"doc(LineSystem.gather by a counting sort of each family's records by line key.

Returns (sums, vis, lines) as LineSystem.gather. transpose: the transposed
operator over the same pairs (sums[partner] += values[x] * cos_x * weight:
x's weight, the partner receives); vis is unchanged by it.)doc");
    t.def("shoot_sender_side", &shoot_sender_side, "system"_a, "emitters"_a.noconvert(),
          "families"_a.noconvert(), "weights"_a.noconvert(), "values"_a.noconvert(),
          "send_scale"_a.noconvert(), "recv_area"_a.noconvert(), "threads"_a = 0,
          "stand_in"_a.noconvert() = py::none(),
          R"doc(LineSystem.shoot with the deposit on the sender side.

Each ray's power values[e] * cos_e * weight * send_scale[e] (send_scale =
area / S) is shared by its receivers in proportion to recv_area * cos_r; hd
holds power. Returns (hd, unfound, rays, steps) as LineSystem.shoot.)doc");
    t.def("input_alignment", &input_alignment, "i32"_a.noconvert(), "i64"_a.noconvert(),
          "f32"_a.noconvert(), "f64"_a.noconvert(),
          "Whether each array, as a kernel sees it, is aligned for its type: (4,) bools.");
    t.def("record_lookup", &record_lookup, "rec_sorted_key"_a.noconvert(),
          "rec_cell_start"_a.noconvert(), "rec_packed"_a.noconvert(), "grid_dims"_a.noconvert(),
          "grid_lo"_a.noconvert(), "grid_origin"_a.noconvert(), "pitch"_a, "y"_a.noconvert(),
          "n"_a.noconvert(), "obj"_a.noconvert(), "reference"_a = false,
          "tri"_a.noconvert() = py::none(), "front"_a.noconvert() = py::none(),
          "piece_first"_a.noconvert() = py::none(), "piece_key"_a.noconvert() = py::none(),
          "piece_record"_a.noconvert() = py::none(), "piece_side"_a.noconvert() = py::none(),
          "piece_plane_first"_a.noconvert() = py::none(), "piece_plane"_a.noconvert() = py::none(),
          R"doc(The record each hit reads, as the gather kernels look it up.

y (H, 3) float64 hit points in the tracer's frame, n (H, 3) float32 unit
normals on the side seen, obj (H,) int32 hit objects; the grid as
voxgi.traced.record_grid returns it (its piece_* too: with tri (H,) int32,
the triangle of each hit, and front (H,) uint8, 1 where it is met on the
side its winding faces, the kernels' lookup reads a listed piece's record).
reference: the search as first written, for comparison (it reads no
pieces). Returns (H,) int64 rows of rec_packed, -1: none.)doc");
}
