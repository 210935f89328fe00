// Phase 3 of the voxelization (see voxelize.cpp): per voxel, clip each
// triangle exactly to the cube, cluster the pieces by object and orientation,
// cut them by the other surfaces' planes, and write the records.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>

#include "voxelize_internal.h"

namespace voxgi {
namespace voxelize_internal {
namespace {

// The largest float32 below 1: the bound of every albedo.
const float kAlbedoMax = std::nextafter(1.0f, 0.0f);

// ---- phase 3: records of one voxel -----------------------------------------

struct Piece {
    int64_t tri;  // the triangle it is a piece of
    int32_t obj;
    int32_t cluster;
    double tn[3];    // the triangle's unit normal (winding)
    double n[3];     // normal aligned with its cluster (flipped for two-sided objects)
    double area;     // voxel units²
    double c[3];     // area-weighted centroid, or the touching point when area == 0
    int v_off, v_n;  // its polygon: vertices [v_off, v_off + v_n) of Scratch::verts
};

struct Cluster {
    int32_t obj;
    int32_t count;
    double seed[3];
    double seed_c[3];  // the first piece's centroid: a point of its plane
    double sum_an[3];
    double sum_n[3];
    double sum_ac[3];
    double sum_a;
};

// A piece, or the part of a piece on one side of the cutting planes.
struct PartRef {
    PolyView poly;
    int piece;
    uint64_t sig;  // bit b set: on the positive side of the cluster's b-th cutting plane
    int layer;     // its piece's layer in the cluster (layer_pieces)
    double area;
    double c[3];
};

struct Scratch {
    std::vector<Piece> pieces;
    std::vector<double> verts;  // piece polygons, 3 doubles per vertex
    std::vector<Cluster> clusters;
    std::vector<int> order, cl_start, cl_items, next;
    std::vector<PartRef> parts, parts2;
    std::vector<int> layer_of;  // per piece (layer_pieces)
    // of one cluster: each part with area, with its record pair (chunk index)
    struct PartRecord {
        int piece;
        uint64_t sig;
        int64_t rec;
    };
    std::vector<PartRecord> part_records;
    std::vector<int> cut_plane;  // of one cluster: the plane (index into planes) of each cut bit
    std::vector<std::pair<double, double>> layer_span;   // scratch: per piece, its range
    std::vector<std::pair<double, double>> layer_range;  // scratch: per layer, its range
    std::deque<Poly> pool;                               // polygons of cut parts (stable addresses)
};

struct ChunkStats {
    int64_t cells = 0, records = 0, back = 0, two_sided = 0, touch = 0, clusters = 0,
            cut_clusters = 0, cut_records = 0, cut_limit = 0, cut_small = 0, overflows = 0,
            layer_records = 0;
};

struct Context {
    const double* tris;
    const int32_t* tri_object;
    const bool* two_sided;
    const float* albedo;
    const float* emission;
    const VoxelizeParams* P;
};

// Exact piece of T in voxel `cell` (closed cube). A triangle lying exactly in
// the plane of a voxel face gives its area to the voxel below that plane
// only, so that no area is counted twice; the voxel above just touches it.
// On the grid's lower boundary (index 0) there is no voxel below: keep it.
void clip_exact(const Tri& T, const int64_t* cell, Poly& out, Poly& tmp) {
    out.n = 0;
    out.overflow = false;
    for (int d = 0; d < 3; ++d)
        if (cell[d] > 0 && T.g[0][d] == double(cell[d]) && T.g[1][d] == double(cell[d]) &&
            T.g[2][d] == double(cell[d]))
            return;
    for (int v = 0; v < 3; ++v) out.push(T.g[v]);
    for (int d = 0; d < 3; ++d) {
        const double lo = double(cell[d]), hi = double(cell[d] + 1);
        const double mn = std::min({T.g[0][d], T.g[1][d], T.g[2][d]});
        const double mx = std::max({T.g[0][d], T.g[1][d], T.g[2][d]});
        if (mn >= lo && mx <= hi) continue;  // inside this slab already: nothing to clip
        clip_axis(out, tmp, d, lo, 1.0);
        clip_axis(tmp, out, d, hi, -1.0);
        if (out.n == 0) return;
    }
}
void clip_grown(const Tri& T, const int64_t* cell, double eps, Poly& out, Poly& tmp) {
    out.n = 0;
    out.overflow = false;
    for (int v = 0; v < 3; ++v) out.push(T.g[v]);
    for (int d = 0; d < 3; ++d) {
        clip_axis(out, tmp, d, double(cell[d]) - eps, 1.0);
        clip_axis(tmp, out, d, double(cell[d] + 1) + eps, -1.0);
        if (out.n == 0) return;
    }
}

void clamp_to_cell(double* p, const int64_t* cell) {
    for (int d = 0; d < 3; ++d)
        p[d] = std::min(double(cell[d] + 1), std::max(double(cell[d]), p[d]));
}

void signed_range(const PolyView& P, const double* n, double off, double& mn, double& mx) {
    mn = std::numeric_limits<double>::infinity();
    mx = -mn;
    for (int i = 0; i < P.n; ++i) {
        const double d = dot3(n, P.v[i]) - off;
        mn = std::min(mn, d);
        mx = std::max(mx, d);
    }
}

// The UV of point x (voxel units) of triangle T (texture.h's corner UVs
// of triangle tri), into uv.
void point_uv(const Tri& T, const float* corner_uv, const double x[3], double uv[2]) {
    double b1, b2;
    barycentric(T.g[0], T.g[1], T.g[2], x, b1, b2);
    const double b0 = 1.0 - b1 - b2;
    for (int c = 0; c < 2; ++c)
        uv[c] = b0 * corner_uv[c] + b1 * corner_uv[2 + c] + b2 * corner_uv[4 + c];
}

// The mean of texture tex over the parts [begin, end) of one record (their
// polygons fanned into triangles, each averaged in UV space and weighted by
// its area); at the parts' points when none has area. Into albedo (3,).
void record_texture_mean(const Context& ctx, const Texture& tex, const std::vector<Piece>& pieces,
                         const std::vector<PartRef>& parts, size_t begin, size_t end,
                         float albedo[3]) {
    const SurfaceTextures& st = *ctx.P->textures;
    double area_sum[3] = {0, 0, 0}, point_sum[3] = {0, 0, 0}, wsum = 0.0;
    int points = 0;
    for (size_t q = begin; q < end; ++q) {
        const PartRef& pt = parts[q];
        const Piece& pc = pieces[pt.piece];
        Tri T;
        if (!load_tri(ctx.tris, pc.tri, *ctx.P, T)) continue;
        const float* cuv = st.corner_uv + 6 * pc.tri;
        if (!(pt.area > 0) || pt.poly.n < 3) {
            double uv[2];
            point_uv(T, cuv, pt.c, uv);
            float f[3];
            texture_eval(tex, uv[0], uv[1], f);
            for (int c = 0; c < 3; ++c) point_sum[c] += f[c];
            ++points;
            continue;
        }
        const double* a = pt.poly.v[0];
        double uv[3][2];
        point_uv(T, cuv, a, uv[0]);
        for (int i = 1; i + 1 < pt.poly.n; ++i) {
            const double *b = pt.poly.v[i], *c = pt.poly.v[i + 1];
            const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            double cr[3];
            cross3(e1, e2, cr);
            const double w = 0.5 * std::sqrt(dot3(cr, cr));
            if (!(w > 0)) continue;
            point_uv(T, cuv, b, uv[1]);
            point_uv(T, cuv, c, uv[2]);
            double m[3];
            texture_triangle_mean(tex, uv, m);
            for (int d = 0; d < 3; ++d) area_sum[d] += w * m[d];
            wsum += w;
        }
    }
    for (int d = 0; d < 3; ++d)
        albedo[d] = float(wsum > 0 ? area_sum[d] / wsum : point_sum[d] / std::max(points, 1));
}

void emit_records(const Context& ctx, const int64_t* cell, const Cluster& cl,
                  const std::vector<Piece>& pieces, const std::vector<PartRef>& parts, size_t begin,
                  size_t end, std::vector<VoxelRecord>& out, ChunkStats& cs) {
    const VoxelizeParams& P = *ctx.P;
    double sa = 0, san[3] = {0, 0, 0}, sn[3] = {0, 0, 0}, sac[3] = {0, 0, 0};
    int n_pos = 0;
    for (size_t q = begin; q < end; ++q) {
        const PartRef& pt = parts[q];
        const Piece& pc = pieces[pt.piece];
        sa += pt.area;
        for (int d = 0; d < 3; ++d) {
            san[d] += pt.area * pc.n[d];
            sn[d] += pc.n[d];
            sac[d] += pt.area * pt.c[d];
        }
        if (pt.area > 0) ++n_pos;
    }
    double nrm[3];
    double len = std::sqrt(dot3(san, san));
    if (sa > 0 && len > 0) {
        for (int d = 0; d < 3; ++d) nrm[d] = san[d] / len;
    } else {
        len = std::sqrt(dot3(sn, sn));  // > 0: all normals lie within 60° of the seed
        for (int d = 0; d < 3; ++d) nrm[d] = sn[d] / len;
    }
    double cen[3];
    if (sa > 0) {
        for (int d = 0; d < 3; ++d) cen[d] = sac[d] / sa;
        if (n_pos > 1) {
            // The mean of several pieces may lie off a curved or folded
            // surface: snap it onto the nearest piece (the VPL must sit on it).
            double best = std::numeric_limits<double>::infinity(), q[3],
                   bq[3] = {cen[0], cen[1], cen[2]};
            for (size_t k = begin; k < end; ++k) {
                const PartRef& pt = parts[k];
                if (!(pt.area > 0)) continue;
                const double dd = closest_on_poly(pt.poly, pieces[pt.piece].tn, cen, q);
                if (dd < best) {
                    best = dd;
                    std::memcpy(bq, q, sizeof(q));
                }
            }
            std::memcpy(cen, bq, sizeof(bq));
        }
    } else {
        // Touching only: the touching point nearest to their mean.
        double m[3] = {0, 0, 0};
        for (size_t k = begin; k < end; ++k)
            for (int d = 0; d < 3; ++d) m[d] += parts[k].c[d] / double(end - begin);
        double best = std::numeric_limits<double>::infinity();
        for (size_t k = begin; k < end; ++k) {
            const double dv[3] = {parts[k].c[0] - m[0], parts[k].c[1] - m[1], parts[k].c[2] - m[2]};
            const double dd = dot3(dv, dv);
            if (dd < best) {
                best = dd;
                std::memcpy(cen, parts[k].c, sizeof(cen));
            }
        }
        ++cs.touch;
    }
    clamp_to_cell(cen, cell);
    const SurfaceTextures* tx = P.textures;
    const int32_t tk = tx && tx->object_texture ? tx->object_texture[cl.obj] : -1;
    float tex_albedo[3];
    if (tk >= 0) {
        record_texture_mean(ctx, tx->textures[tk], pieces, parts, begin, end, tex_albedo);
        // below 1 in float32, as every albedo the solve takes (docs/design.md §12)
        for (int d = 0; d < 3; ++d)
            tex_albedo[d] = std::min(std::max(tex_albedo[d], 0.0f), kAlbedoMax);
    }
    VoxelRecord r;
    for (int d = 0; d < 3; ++d) {
        r.ijk[d] = static_cast<int32_t>(cell[d]);
        r.normal[d] = static_cast<float>(nrm[d]);
        r.albedo[d] = tk >= 0 ? tex_albedo[d] : ctx.albedo[cl.obj * 3 + d];
        r.emission[d] = ctx.emission[cl.obj * 3 + d];
        r.centroid[d] = P.origin[d] + cen[d] * P.pitch;
    }
    r.object = cl.obj;
    r.area = static_cast<float>(sa * P.pitch * P.pitch);
    r.back = 0;
    r.side = 0;
    out.push_back(r);
    // The reverse side: live for a two-sided object, black (but opaque) otherwise.
    for (int d = 0; d < 3; ++d) r.normal[d] = -r.normal[d];
    r.side = 1;
    if (ctx.two_sided[cl.obj]) {
        ++cs.two_sided;
    } else {
        r.back = 1;
        for (int d = 0; d < 3; ++d) r.albedo[d] = r.emission[d] = 0.0f;
        ++cs.back;
    }
    out.push_back(r);
    cs.records += 2;
}

// The piece of each triangle in the cell (clipped exactly; a triangle that
// only touches the cell gets a point of itself), into S.pieces and S.verts.
int clip_pieces(const Context& ctx, const int64_t cell[3], const Pair* pairs, int64_t np,
                Scratch& S, ChunkStats& cs) {
    const VoxelizeParams& P = *ctx.P;
    auto& pieces = S.pieces;
    if (pieces.size() < size_t(np)) pieces.resize(size_t(np));
    int n_pieces = 0;
    Poly tmp, work;
    auto& verts = S.verts;
    verts.clear();
    for (int64_t q = 0; q < np; ++q) {
        Tri T;
        if (!load_tri(ctx.tris, pairs[q].tri, P, T)) continue;  // counted in phase 1
        Piece& pc = pieces[n_pieces++];
        pc.tri = pairs[q].tri;
        pc.obj = ctx.tri_object[pairs[q].tri];
        pc.cluster = -1;
        std::memcpy(pc.tn, T.n, sizeof(T.n));
        std::memcpy(pc.n, T.n, sizeof(T.n));
        Poly& poly = work;
        clip_exact(T, cell, poly, tmp);
        pc.area = poly.n >= 3 ? area_centroid(view(poly), T.n, pc.c) : 0.0;
        if (!(pc.area > 0)) {
            // Touches the closed cube (within eps) without area inside it.
            pc.area = 0;
            if (poly.n == 0) clip_grown(T, cell, P.eps, poly, tmp);
            if (poly.n == 0) clip_grown(T, cell, 4 * P.eps, poly, tmp);
            if (poly.n == 0) {
                poly.push(T.g[0]);  // cannot happen short of round-off trouble
                poly.push(T.g[1]);
                poly.push(T.g[2]);
            }
            // The vertex mean of the (grown) piece: a point of the triangle.
            pc.c[0] = pc.c[1] = pc.c[2] = 0;
            for (int i = 0; i < poly.n; ++i)
                for (int d = 0; d < 3; ++d) pc.c[d] += poly.v[i][d] / poly.n;
            clamp_to_cell(pc.c, cell);
        }
        if (poly.overflow) ++cs.overflows;
        pc.v_off = int(verts.size() / 3);
        pc.v_n = poly.n;
        verts.insert(verts.end(), &poly.v[0][0], &poly.v[0][0] + 3 * poly.n);
    }
    return n_pieces;
}

// Whether piece pc meets the plane of cluster cl's first piece: has vertices
// on both sides of it or on it, within kMeetsPlane voxel units.
constexpr double kMeetsPlane = 1e-3;
bool meets_plane(const Piece& pc, const Cluster& cl, const std::vector<double>& verts) {
    const PolyView poly{reinterpret_cast<const double (*)[3]>(verts.data() + 3 * size_t(pc.v_off)),
                        pc.v_n};
    double mn, mx;
    signed_range(poly, cl.seed, dot3(cl.seed, cl.seed_c), mn, mx);
    return mn <= kMeetsPlane && mx >= -kMeetsPlane;
}

// Clusters: per object (ascending), greedy by orientation in triangle order;
// then the pieces of each cluster, in the order they joined it (S.cl_start,
// S.cl_items).
void cluster_pieces(const Context& ctx, int n_pieces, Scratch& S, ChunkStats& cs) {
    const VoxelizeParams& P = *ctx.P;
    auto& pieces = S.pieces;
    auto& order = S.order;
    order.resize(size_t(n_pieces));
    for (int q = 0; q < n_pieces; ++q) order[q] = q;
    // Objects are usually in order already (triangles come object by object).
    auto by_obj = [&](int x, int y) { return pieces[x].obj < pieces[y].obj; };
    if (!std::is_sorted(order.begin(), order.end(), by_obj))
        std::stable_sort(order.begin(), order.end(), by_obj);
    auto& clusters = S.clusters;
    clusters.clear();
    size_t obj_first = 0;
    for (int idx : order) {
        Piece& pc = pieces[idx];
        if (clusters.empty() || clusters.back().obj != pc.obj) obj_first = clusters.size();
        const bool ts = ctx.two_sided[pc.obj];
        int found = -1;
        for (size_t q = obj_first; q < clusters.size(); ++q) {
            const double dd = dot3(pc.tn, clusters[q].seed);
            // Two-sided surfaces have no preferred side: a flipped winding
            // that meets the cluster's plane joins it with its normal turned
            // around. One wholly in front of or behind that plane is another
            // face (the far face of a two-sided slab thinner than a voxel),
            // whose two sides must stay records of their own.
            if (dd >= P.cos_cluster ||
                (ts && -dd >= P.cos_cluster && meets_plane(pc, clusters[q], S.verts))) {
                found = int(q);
                if (dd < 0)
                    for (int d = 0; d < 3; ++d) pc.n[d] = -pc.tn[d];
                break;
            }
        }
        if (found < 0) {
            Cluster c{};
            c.obj = pc.obj;
            std::memcpy(c.seed, pc.tn, sizeof(c.seed));
            std::memcpy(c.seed_c, pc.c, sizeof(c.seed_c));
            clusters.push_back(c);
            found = int(clusters.size() - 1);
        }
        Cluster& c = clusters[found];
        pc.cluster = found;
        ++c.count;
        c.sum_a += pc.area;
        for (int d = 0; d < 3; ++d) {
            c.sum_an[d] += pc.area * pc.n[d];
            c.sum_n[d] += pc.n[d];
            c.sum_ac[d] += pc.area * pc.c[d];
        }
    }
    const size_t ncl = clusters.size();
    cs.clusters += int64_t(ncl);
    auto& cl_start = S.cl_start;
    auto& cl_items = S.cl_items;
    cl_start.assign(ncl + 1, 0);
    for (size_t q = 0; q < ncl; ++q) cl_start[q + 1] = cl_start[q] + clusters[q].count;
    cl_items.resize(size_t(n_pieces));
    {
        auto& next = S.next;
        next.assign(cl_start.begin(), cl_start.end() - 1);
        for (int idx : order) cl_items[size_t(next[size_t(pieces[idx].cluster)]++)] = idx;
    }
}

// A cutting plane: through a cluster's area-weighted centroid, normal to its
// area-weighted normal (ok: the cluster has area; separates: the cluster
// covers enough of the voxel's section by that plane to part it).
struct Plane {
    double n[3], off;
    bool ok, separates;
};

// The area of the section of the unit cube `cell` by the plane n·x = off
// (voxel units²): a square on the plane wider than the cube, clipped to it.
double section_area(const double n[3], double off, const int64_t* cell) {
    double c[3];
    for (int d = 0; d < 3; ++d) c[d] = double(cell[d]) + 0.5;
    const double s = dot3(n, c) - off;
    for (int d = 0; d < 3; ++d) c[d] -= s * n[d];
    // an axis of the plane: n crossed with the coordinate axis least along it
    int m = 0;
    for (int d = 1; d < 3; ++d)
        if (std::fabs(n[d]) < std::fabs(n[m])) m = d;
    double e[3] = {0.0, 0.0, 0.0}, a[3], b[3];
    e[m] = 1.0;
    cross3(n, e, a);
    const double la = std::sqrt(dot3(a, a));
    for (int d = 0; d < 3; ++d) a[d] /= la;
    cross3(n, a, b);
    Poly q, tmp;
    q.n = 0;
    q.overflow = false;
    const double corner[4][2] = {{-2, -2}, {2, -2}, {2, 2}, {-2, 2}};  // half-width 2 > √3/2
    for (const auto& k : corner) {
        double v[3];
        for (int d = 0; d < 3; ++d) v[d] = c[d] + k[0] * a[d] + k[1] * b[d];
        q.push(v);
    }
    for (int d = 0; d < 3; ++d) {
        clip_axis(q, tmp, d, double(cell[d]), 1.0);
        clip_axis(tmp, q, d, double(cell[d] + 1), -1.0);
        if (q.n == 0) return 0.0;
    }
    double ctr[3];
    return q.n >= 3 ? area_centroid(view(q), n, ctr) : 0.0;
}

void cutting_planes(const std::vector<Cluster>& clusters, const int64_t* cell, Plane planes[64],
                    ChunkStats& cs) {
    const size_t ncl = clusters.size();
    for (size_t q = 0; q < ncl && q < 64; ++q) {
        const Cluster& c = clusters[q];
        const double len = std::sqrt(dot3(c.sum_an, c.sum_an));
        planes[q].ok = c.sum_a > 0 && len > 0;
        planes[q].separates = false;
        if (!planes[q].ok) continue;
        double ctr[3];
        for (int d = 0; d < 3; ++d) {
            planes[q].n[d] = c.sum_an[d] / len;
            ctr[d] = c.sum_ac[d] / c.sum_a;
        }
        planes[q].off = dot3(planes[q].n, ctr);
        planes[q].separates =
            c.sum_a >= kSeparatingShare * section_area(planes[q].n, planes[q].off, cell);
        if (!planes[q].separates) ++cs.cut_small;
    }
}

// Whether a piece of cluster q comes within kTouch voxel units of plane pl.
bool touches(const Scratch& S, size_t q, const Plane& pl) {
    for (int k = S.cl_start[q]; k < S.cl_start[q + 1]; ++k) {
        const Piece& pc = S.pieces[S.cl_items[k]];
        const PolyView pv{
            reinterpret_cast<const double (*)[3]>(S.verts.data() + 3 * size_t(pc.v_off)), pc.v_n};
        double mn, mx;
        signed_range(pv, pl.n, pl.off, mn, mx);
        if (mn <= kTouch && mx >= -kTouch) return true;
    }
    return false;
}

// Cut the parts of cluster ci (S.parts) by the planes of the other clusters
// that they straddle; each part's sig gets one bit per cut (its side).
// Returns the cuts made.
int cut_cluster(const Context& ctx, size_t ci, size_t ncl, const Plane* planes, Scratch& S,
                ChunkStats& cs) {
    const VoxelizeParams& P = *ctx.P;
    const auto& pieces = S.pieces;
    auto& parts = S.parts;
    auto& parts2 = S.parts2;
    auto& pool = S.pool;
    int n_cuts = 0;
    S.cut_plane.clear();
    {
        for (size_t sj = 0; sj < ncl && sj < 64; ++sj) {
            if (sj == ci || !planes[sj].ok) continue;
            const Plane& pl = planes[sj];
            // A small surface (one that covers a small share of the voxel's
            // section by its plane: a trinket, a facet of a small curved
            // object) parts nothing a small cluster has: light goes round
            // both inside the voxel. Cut by each other's planes, a voxel of
            // a few small curved objects split into thousands of records,
            // each lookup in it asking all of them. A large cluster is still
            // cut by a small surface's plane: a lamp's low sides bound its
            // footprint on the ceiling, which is then buried (§2).
            const bool ci_large = ci < 64 && planes[ci].ok && planes[ci].separates;
            if (!pl.separates && !ci_large) continue;
            // and only where the small surface meets it: a trinket
            // standing clear of a wall bounds nothing on it.
            if (!pl.separates && !touches(S, sj, planes[ci])) continue;
            // A surface of the same orientation (as clustering judges it)
            // is the same sheet continued, e.g. where two objects of one
            // curved surface meet: nothing to separate.
            if (ci < 64 && planes[ci].ok && dot3(pl.n, planes[ci].n) >= P.cos_cluster) continue;
            bool straddles = false;
            for (const PartRef& pt : parts) {
                if (!(pt.area > 0)) continue;
                double mn, mx;
                signed_range(pt.poly, pl.n, pl.off, mn, mx);
                if (mx > P.cut_delta && mn < -P.cut_delta) {
                    straddles = true;
                    break;
                }
            }
            if (!straddles) continue;
            if (n_cuts == kMaxCuts) {
                ++cs.cut_limit;
                continue;
            }
            const uint64_t bit = uint64_t(1) << n_cuts++;
            S.cut_plane.push_back(int(sj));
            parts2.clear();
            for (const PartRef& pt : parts) {
                double mn = 0, mx = 0;
                if (pt.area > 0) signed_range(pt.poly, pl.n, pl.off, mn, mx);
                if (pt.area > 0 && mx > P.cut_delta && mn < -P.cut_delta) {
                    const double* tn = pieces[pt.piece].tn;
                    for (int s = 0; s < 2; ++s) {
                        pool.emplace_back();
                        Poly& poly = pool.back();
                        clip_plane(pt.poly, poly, pl.n, pl.off, s == 0 ? 1.0 : -1.0);
                        if (poly.n == 0) continue;
                        PartRef np_{view(poly), pt.piece, pt.sig | (s == 0 ? bit : 0),
                                    pt.layer,   0.0,      {0, 0, 0}};
                        np_.area = poly.n >= 3 ? area_centroid(view(poly), tn, np_.c) : 0.0;
                        if (!(np_.area > 0)) {
                            np_.area = 0;
                            area_centroid(view(poly), tn, np_.c);
                        }
                        if (poly.overflow) ++cs.overflows;
                        parts2.push_back(np_);
                    }
                } else {
                    parts2.push_back(pt);
                    if (dot3(pl.n, pt.c) - pl.off >= 0) parts2.back().sig |= bit;
                }
            }
            parts.swap(parts2);
        }
    }
    return n_cuts;
}

// The layers of cluster ci: its pieces with area, in order of their least
// distance along the cluster's normal, split wherever the next one starts
// over kLayerGap beyond the furthest so far. A connected sheet, however
// curved within the voxel, is one layer (its neighbouring pieces share
// edges, so their ranges meet); a stack of separate parallel sheets finer
// than a voxel (blinds, shelves, treads) is one layer per sheet. Lumped
// into one record, the sheets of a stack would share one radiosity and one
// point: a ray landing in the gap between two slats would read the mean of
// every slat of the voxel, and rays from the record's point would see past
// the slats it stands for. Pieces without area join the layer nearest them.
// Into S.layer_of (per piece); returns the number of layers.
int layer_pieces(size_t ci, Scratch& S) {
    const Cluster& c = S.clusters[ci];
    const int b = S.cl_start[ci], e = S.cl_start[ci + 1];
    double n[3];
    const double len = std::sqrt(dot3(c.sum_an, c.sum_an));
    for (int d = 0; d < 3; ++d) n[d] = len > 0 ? c.sum_an[d] / len : c.seed[d];
    auto& span = S.layer_span;  // (least, greatest) distance, per item of the cluster
    span.resize(size_t(e - b));
    auto& order = S.next;
    order.clear();
    for (int k = b; k < e; ++k) {
        const Piece& pc = S.pieces[S.cl_items[k]];
        const PolyView pv{
            reinterpret_cast<const double (*)[3]>(S.verts.data() + 3 * size_t(pc.v_off)), pc.v_n};
        double mn = dot3(n, pc.c), mx = mn;
        if (pc.area > 0) {
            signed_range(pv, n, 0.0, mn, mx);
            order.push_back(k - b);
        }
        span[size_t(k - b)] = {mn, mx};
    }
    std::stable_sort(order.begin(), order.end(),
                     [&](int x, int y) { return span[size_t(x)].first < span[size_t(y)].first; });
    // layers as ranges [lo, hi] of distance, in order
    auto& layers = S.layer_range;
    layers.clear();
    for (int i : order) {
        const auto& sp = span[size_t(i)];
        if (layers.empty() || sp.first > layers.back().second + kLayerGap)
            layers.push_back(sp);
        else
            layers.back().second = std::max(layers.back().second, sp.second);
        S.layer_of[size_t(S.cl_items[size_t(b + i)])] = int(layers.size()) - 1;
    }
    for (int k = b; k < e; ++k) {
        const Piece& pc = S.pieces[S.cl_items[k]];
        if (pc.area > 0) continue;
        int best = 0;
        double best_d = std::numeric_limits<double>::infinity();
        const auto& sp = span[size_t(k - b)];
        for (size_t l = 0; l < layers.size(); ++l) {
            const double d =
                std::max({layers[l].first - sp.second, sp.first - layers[l].second, 0.0});
            if (d < best_d) best_d = d, best = int(l);
        }
        S.layer_of[size_t(S.cl_items[k])] = best;
    }
    return std::max<int>(1, int(layers.size()));
}

// The surface pieces of one cluster, from its parts with area and their
// record pairs (S.part_records): a piece whose parts all went to one pair
// once, without planes; a piece the cutting planes split once per pair,
// with the planes whose sides its parts differ on (S.cut_plane) and the
// part's side of each. The record on the triangle's winding side is the
// pair's front (side 0) unless the piece was turned to its cluster (a
// two-sided object's reversed face).
void list_pieces(Scratch& S, const Plane* planes, VoxelChunk& out) {
    auto& pr = S.part_records;
    std::sort(pr.begin(), pr.end(), [](const auto& x, const auto& y) {
        return x.piece < y.piece || (x.piece == y.piece && x.sig < y.sig);
    });
    for (size_t b = 0, e; b < pr.size(); b = e) {
        uint64_t differ = 0;
        for (e = b + 1; e < pr.size() && pr[e].piece == pr[b].piece; ++e)
            differ |= pr[e].sig ^ pr[b].sig;
        const Piece& pc = S.pieces[size_t(pr[b].piece)];
        const bool turned = dot3(pc.n, pc.tn) < 0.0;
        for (size_t k = b; k < e; ++k) {
            if (k > b && pr[k].sig == pr[k - 1].sig) continue;  // the same part's record
            const int64_t r = pr[k].rec;
            SurfacePiece sp{int32_t(pc.tri), int32_t(turned ? r + 1 : r),
                            int32_t(turned ? r : r + 1), 0u, 0};
            for (int bit = 0; bit < 64; ++bit) {
                if (!((differ >> bit) & 1)) continue;
                const Plane& pl = planes[S.cut_plane[size_t(bit)]];
                out.planes.insert(out.planes.end(), {pl.n[0], pl.n[1], pl.n[2], pl.off});
                if ((pr[k].sig >> bit) & 1) sp.side |= 1u << sp.n_planes;
                ++sp.n_planes;
            }
            out.pieces.push_back(sp);
        }
    }
}

void process_cell(const Context& ctx, uint64_t key, const Pair* pairs, int64_t np, Scratch& S,
                  VoxelChunk& out, ChunkStats& cs) {
    const VoxelizeParams& P = *ctx.P;
    const uint64_t D1 = P.dims[1], D2 = P.dims[2];
    const int64_t cell[3] = {int64_t(key / (D1 * D2)), int64_t((key / D2) % D1), int64_t(key % D2)};
    const int n_pieces = clip_pieces(ctx, cell, pairs, np, S, cs);
    if (n_pieces == 0) return;
    ++cs.cells;
    cluster_pieces(ctx, n_pieces, S, cs);
    const auto& clusters = S.clusters;
    const auto& pieces = S.pieces;
    const size_t ncl = clusters.size();
    Plane planes[64];
    const bool do_cut = P.cut && ncl > 1;
    if (do_cut) cutting_planes(clusters, cell, planes, cs);
    auto& parts = S.parts;
    S.pool.clear();
    S.layer_of.assign(size_t(n_pieces), 0);
    for (size_t ci = 0; ci < ncl; ++ci) {
        const Cluster& cl = clusters[ci];
        const int n_layers = S.cl_start[ci + 1] - S.cl_start[ci] > 1 ? layer_pieces(ci, S) : 1;
        parts.clear();
        for (int q = S.cl_start[ci]; q < S.cl_start[ci + 1]; ++q) {
            const int idx = S.cl_items[q];
            const Piece& pc = pieces[idx];
            const PolyView pv{
                reinterpret_cast<const double (*)[3]>(S.verts.data() + 3 * size_t(pc.v_off)),
                pc.v_n};
            parts.push_back(
                PartRef{pv, idx, 0, S.layer_of[size_t(idx)], pc.area, {pc.c[0], pc.c[1], pc.c[2]}});
        }
        const int n_cuts = do_cut ? cut_cluster(ctx, ci, ncl, planes, S, cs) : 0;
        if (n_cuts > 0 || n_layers > 1)
            std::stable_sort(parts.begin(), parts.end(), [](const PartRef& x, const PartRef& y) {
                return x.layer < y.layer || (x.layer == y.layer && x.sig < y.sig);
            });
        // one record per layer and side of the cutting planes
        S.part_records.clear();
        size_t b = 0, n_rec = 0;
        while (b < parts.size()) {
            size_t e = b + 1;
            while (e < parts.size() && parts[e].sig == parts[b].sig &&
                   parts[e].layer == parts[b].layer)
                ++e;
            const int64_t rec = int64_t(out.records.size());
            for (size_t q = b; q < e; ++q)
                if (parts[q].area > 0)
                    S.part_records.push_back({parts[q].piece, parts[q].sig, rec});
            emit_records(ctx, cell, cl, pieces, parts, b, e, out.records, cs);
            ++n_rec;
            b = e;
        }
        cs.layer_records += int64_t(n_layers - 1);
        if (n_rec > size_t(n_layers)) {
            ++cs.cut_clusters;
            cs.cut_records += int64_t(n_rec) - n_layers;
        }
        list_pieces(S, planes, out);
    }
}

}  // namespace

std::vector<VoxelChunk> cell_records(const double* tris, const int32_t* tri_object,
                                     const bool* two_sided, const float* albedo,
                                     const float* emission, const VoxelizeParams& P,
                                     const std::vector<Pair>& pairs,
                                     const std::vector<int64_t>& starts, int threads,
                                     const StopCheck& stop, VoxelizeStats& st,
                                     VoxelizeProgress* progress) {
    const size_t n_pairs = pairs.size();
    const int64_t n_cells = int64_t(starts.size()) - 1;
    const auto t0 = Clock::now();
    const int64_t cell_chunk =
        std::max<int64_t>(256, std::min<int64_t>(16384, n_cells / (int64_t(threads) * 16) + 1));
    const int64_t n_cchunks = (n_cells + cell_chunk - 1) / cell_chunk;
    std::vector<VoxelChunk> out(n_cchunks);
    std::vector<ChunkStats> cstats(n_cchunks);
    std::vector<Scratch> scratch(threads);
    Context ctx{tris, tri_object, two_sided, albedo, emission, &P};
    set_phase(progress, 3, n_cells);
    parallel_for(n_cchunks, threads, stop, [&](int64_t ch, int th) {
        const int64_t c_end = std::min(n_cells, (ch + 1) * cell_chunk);
        auto& o = out[ch];
        // front + reverse per voxel, usually
        o.records.reserve(size_t(c_end - ch * cell_chunk) * 2 + 16);
        for (int64_t c = ch * cell_chunk; c < c_end; ++c)
            process_cell(ctx, pairs[starts[c]].key, pairs.data() + starts[c],
                         starts[c + 1] - starts[c], scratch[th], o, cstats[ch]);
        if (progress) progress->done += c_end - ch * cell_chunk;
    });
    size_t rec_bytes = 0;
    for (int64_t ch = 0; ch < n_cchunks; ++ch) {
        const ChunkStats& cs = cstats[ch];
        st.cells += cs.cells;
        st.records += cs.records;
        st.back_records += cs.back;
        st.two_sided_records += cs.two_sided;
        st.touch_records += cs.touch;
        st.clusters += cs.clusters;
        st.cut_clusters += cs.cut_clusters;
        st.cut_records += cs.cut_records;
        st.cut_limit_hits += cs.cut_limit;
        st.cut_small_planes += cs.cut_small;
        st.polygon_overflows += cs.overflows;
        st.layer_records += cs.layer_records;
        rec_bytes += out[ch].records.capacity() * sizeof(VoxelRecord) +
                     out[ch].pieces.capacity() * sizeof(SurfacePiece) +
                     out[ch].planes.capacity() * sizeof(double);
    }
    st.peak_bytes = std::max<int64_t>(
        st.peak_bytes,
        int64_t(n_pairs * sizeof(Pair) + starts.size() * sizeof(int64_t) + rec_bytes));
    st.seconds_records = seconds_since(t0);
    return out;
}

}  // namespace voxelize_internal
}  // namespace voxgi
