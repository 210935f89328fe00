// Exact sparse supercover voxelization (see voxelize.h).
//
// Three phases, each deterministic whatever the thread count:
//  1. per triangle (threads over chunks of triangles): the voxels whose closed
//     cube, grown by eps, meets it, found by clipping the triangle to slabs
//     along two axes and reading the range along the third (work follows the
//     output, never the bounding box); emits (voxel key, triangle) pairs;
//  2. a stable LSD radix sort of the pairs by voxel key (ties keep triangle
//     order, so the pair list is fully determined);
//  3. per voxel (threads over chunks of voxels): clip each triangle exactly to
//     the cube, cluster the pieces by object and orientation, cut them by the
//     other surfaces' planes, and write the records.
//
// Phases 1 and 2 and the checks live here; phase 3 in voxelize_records.cpp.
#include "voxelize.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "voxelize_internal.h"

namespace voxgi {
namespace {

using namespace voxelize_internal;

inline int64_t ifloor(double x) { return static_cast<int64_t>(std::floor(x)); }
inline int64_t iceil(double x) { return static_cast<int64_t>(std::ceil(x)); }

// Phase 1 for one triangle: append the keys of every voxel whose cube, grown
// by eps, meets the triangle.
void triangle_cells(const Tri& T, uint32_t tri, const VoxelizeParams& P, std::vector<Pair>& out,
                    int64_t& overflows) {
    const double eps = P.eps;
    const int64_t D1 = P.dims[1], D2 = P.dims[2];
    // Voxel i along an axis meets [lo - eps, hi + eps] iff i <= hi + eps and i + 1 >= lo - eps.
    int64_t lo[3], hi[3];
    for (int d = 0; d < 3; ++d) {
        const double mn = std::min({T.g[0][d], T.g[1][d], T.g[2][d]});
        const double mx = std::max({T.g[0][d], T.g[1][d], T.g[2][d]});
        lo[d] = std::max<int64_t>(0, iceil(mn - eps - 1.0));
        hi[d] = std::min<int64_t>(P.dims[d] - 1, ifloor(mx + eps));
    }
    auto emit = [&](int64_t i, int64_t j, int64_t k) {
        out.push_back({static_cast<uint64_t>((i * D1 + j) * D2 + k), tri});
    };
    if (lo[0] == hi[0] && lo[1] == hi[1] && lo[2] == hi[2]) {  // small triangle: one voxel
        emit(lo[0], lo[1], lo[2]);
        return;
    }
    // Slabs along the two axes where the triangle is widest in projection;
    // the range along the dominant normal axis c is then short (1-2 voxels).
    int c = 0;
    for (int d = 1; d < 3; ++d)
        if (std::fabs(T.n[d]) > std::fabs(T.n[c])) c = d;
    const int a = (c + 1) % 3, b = (c + 2) % 3;
    Poly tri0, s1, s2, t1, t2;
    for (int v = 0; v < 3; ++v) tri0.push(T.g[v]);
    int64_t cell[3];
    for (int64_t i = lo[a]; i <= hi[a]; ++i) {
        clip_axis(tri0, t1, a, double(i) - eps, 1.0);
        clip_axis(t1, s1, a, double(i + 1) + eps, -1.0);
        if (s1.n == 0) continue;
        double bmn = s1.v[0][b], bmx = bmn;
        for (int q = 1; q < s1.n; ++q) {
            bmn = std::min(bmn, s1.v[q][b]);
            bmx = std::max(bmx, s1.v[q][b]);
        }
        const int64_t jlo = std::max<int64_t>(lo[b], iceil(bmn - eps - 1.0));
        const int64_t jhi = std::min<int64_t>(hi[b], ifloor(bmx + eps));
        for (int64_t j = jlo; j <= jhi; ++j) {
            clip_axis(s1, t2, b, double(j) - eps, 1.0);
            clip_axis(t2, s2, b, double(j + 1) + eps, -1.0);
            if (s2.n == 0) continue;
            if (s2.overflow) ++overflows;
            double cmn = s2.v[0][c], cmx = cmn;
            for (int q = 1; q < s2.n; ++q) {
                cmn = std::min(cmn, s2.v[q][c]);
                cmx = std::max(cmx, s2.v[q][c]);
            }
            const int64_t klo = std::max<int64_t>(lo[c], iceil(cmn - eps - 1.0));
            const int64_t khi = std::min<int64_t>(hi[c], ifloor(cmx + eps));
            cell[a] = i;
            cell[b] = j;
            for (int64_t k = klo; k <= khi; ++k) {
                cell[c] = k;
                emit(cell[0], cell[1], cell[2]);
            }
        }
    }
}

// Stable LSD radix sort of pairs by key (16-bit digits).
void radix_sort(std::vector<Pair>& v, uint64_t max_key, const StopCheck& stop) {
    if (v.size() < 2) return;
    int bits = 0;
    while (bits < 64 && (max_key >> bits) != 0) ++bits;
    std::vector<Pair> tmp(v.size());
    std::vector<size_t> count(1 << 16);
    for (int shift = 0; shift < bits; shift += 16) {
        std::fill(count.begin(), count.end(), 0);
        for (const Pair& p : v) ++count[(p.key >> shift) & 0xFFFF];
        size_t sum = 0;
        for (auto& cnt : count) {
            const size_t c = cnt;
            cnt = sum;
            sum += c;
        }
        for (const Pair& p : v) tmp[count[(p.key >> shift) & 0xFFFF]++] = p;
        v.swap(tmp);
        if (stop && stop()) throw Interrupted();
    }
}

// The parameters' and the triangle count's ranges (std::invalid_argument).
void check_params(int64_t n_tris, const VoxelizeParams& P) {
    if (!(P.pitch > 0) || !std::isfinite(P.pitch))
        throw std::invalid_argument("voxelize: pitch must be finite and > 0");
    for (int d = 0; d < 3; ++d) {
        if (!std::isfinite(P.origin[d]))
            throw std::invalid_argument("voxelize: origin must be finite");
        if (P.dims[d] < 1 || P.dims[d] >= (1 << 21))
            throw std::invalid_argument("voxelize: dims must lie in [1, 2^21)");
    }
    if (n_tris < 0 || n_tris >= (int64_t(1) << 32))
        throw std::invalid_argument("voxelize: too many triangles (at most 2^32 - 1)");
    if (!(P.eps >= 0 && P.eps < 0.01))
        throw std::invalid_argument("voxelize: eps must be in [0, 0.01)");
    if (!(P.cos_cluster >= -1 && P.cos_cluster <= 1))
        throw std::invalid_argument("voxelize: cos_cluster must be in [-1, 1]");
}

// Phase 1: the (voxel, triangle) pairs of every triangle, in triangle order;
// checks each triangle's object and vertices.
std::vector<Pair> triangle_pairs(const double* tris, int64_t n_tris, const int32_t* tri_object,
                                 int32_t n_objects, const VoxelizeParams& P, int threads,
                                 const StopCheck& stop, VoxelizeStats& st,
                                 VoxelizeProgress* progress) {
    auto t0 = Clock::now();
    // Small chunks when there are few triangles: the calling thread polls
    // Ctrl-C only between chunks, and one large triangle at a high resolution
    // is already ~1e6 cells, so a chunk of many such triangles would keep
    // Ctrl-C waiting for seconds.
    const int64_t tri_chunk =
        std::max<int64_t>(1, std::min<int64_t>(2048, n_tris / (int64_t(threads) * 64)));
    const int64_t n_tchunks = (n_tris + tri_chunk - 1) / tri_chunk;
    std::vector<std::vector<Pair>> chunk_pairs(n_tchunks);
    std::vector<int64_t> chunk_skipped(n_tchunks, 0), chunk_overflow(n_tchunks, 0);
    set_phase(progress, 1, n_tris);
    parallel_for(n_tchunks, threads, stop, [&](int64_t ch, int) {
        const int64_t t_end = std::min(n_tris, (ch + 1) * tri_chunk);
        auto& out = chunk_pairs[ch];
        out.reserve(size_t(t_end - ch * tri_chunk) * 4);
        for (int64_t t = ch * tri_chunk; t < t_end; ++t) {
            const int32_t o = tri_object[t];
            if (o < 0 || o >= n_objects)
                throw std::invalid_argument("voxelize: tri_object[" + std::to_string(t) +
                                            "] = " + std::to_string(o) + " is not in [0, " +
                                            std::to_string(n_objects) + ")");
            Tri T;
            bool finite = true, inside = true;
            for (int v = 0; v < 9; ++v) finite = finite && std::isfinite(tris[t * 9 + v]);
            if (!finite)
                throw std::invalid_argument("voxelize: triangle " + std::to_string(t) +
                                            " has a non-finite vertex");
            const bool ok = load_tri(tris, t, P, T);
            for (int v = 0; v < 3; ++v)
                for (int d = 0; d < 3; ++d)
                    inside = inside && T.g[v][d] >= -1e-6 && T.g[v][d] <= P.dims[d] + 1e-6;
            if (!inside)
                throw std::invalid_argument("voxelize: triangle " + std::to_string(t) +
                                            " lies outside the grid origin + pitch * [0, dims]");
            if (!ok) {
                ++chunk_skipped[ch];
                continue;
            }
            triangle_cells(T, static_cast<uint32_t>(t), P, out, chunk_overflow[ch]);
        }
        if (progress) progress->done += t_end - ch * tri_chunk;
    });
    size_t n_pairs = 0, chunk_bytes = 0;
    for (int64_t ch = 0; ch < n_tchunks; ++ch) {
        n_pairs += chunk_pairs[ch].size();
        chunk_bytes += chunk_pairs[ch].capacity() * sizeof(Pair);
        st.skipped_degenerate += chunk_skipped[ch];
        st.polygon_overflows += chunk_overflow[ch];
    }
    std::vector<Pair> pairs;
    pairs.reserve(n_pairs);
    st.peak_bytes = int64_t(chunk_bytes + n_pairs * sizeof(Pair));
    for (auto& cp : chunk_pairs) {
        pairs.insert(pairs.end(), cp.begin(), cp.end());
        std::vector<Pair>().swap(cp);
    }
    st.pairs = int64_t(n_pairs);
    st.seconds_pairs = seconds_since(t0);
    return pairs;
}

// Phase 2: sort the pairs by voxel key (stable: ties keep triangle order);
// returns where each voxel's pairs start, then the pair count.
std::vector<int64_t> sort_pairs(std::vector<Pair>& pairs, const VoxelizeParams& P,
                                const StopCheck& stop, VoxelizeStats& st,
                                VoxelizeProgress* progress) {
    const size_t n_pairs = pairs.size();
    const auto t0 = Clock::now();
    set_phase(progress, 2, 1);
    const uint64_t max_key = uint64_t(P.dims[0]) * uint64_t(P.dims[1]) * uint64_t(P.dims[2]);
    radix_sort(pairs, max_key, stop);
    st.peak_bytes = std::max<int64_t>(st.peak_bytes, int64_t(2 * n_pairs * sizeof(Pair)));
    std::vector<int64_t> starts;
    for (size_t q = 0; q < n_pairs; ++q)
        if (q == 0 || pairs[q].key != pairs[q - 1].key) starts.push_back(int64_t(q));
    starts.push_back(int64_t(n_pairs));
    st.seconds_sort = seconds_since(t0);
    return starts;
}

}  // namespace

std::vector<VoxelChunk> voxelize(const double* tris, int64_t n_tris, const int32_t* tri_object,
                                 int32_t n_objects, const bool* two_sided, const float* albedo,
                                 const float* emission, const VoxelizeParams& P, int threads,
                                 const StopCheck& stop, VoxelizeStats& st,
                                 VoxelizeProgress* progress) {
    st = VoxelizeStats{};
    st.triangles = n_tris;
    check_params(n_tris, P);
    threads = resolve_threads(threads);
    std::vector<Pair> pairs =
        triangle_pairs(tris, n_tris, tri_object, n_objects, P, threads, stop, st, progress);
    const std::vector<int64_t> starts = sort_pairs(pairs, P, stop, st, progress);
    return cell_records(tris, tri_object, two_sided, albedo, emission, P, pairs, starts, threads,
                        stop, st, progress);
}

}  // namespace voxgi
