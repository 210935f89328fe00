// Reference and adjoint variants for the tests: the gathering by sorting
// each family's records by line key, with its transpose, and the shooting
// with the deposit on the sender side (docs/design.md §4, §5).
#include "reference.h"

#include <algorithm>
#include <stdexcept>
#include <vector>

#include "lineorder.h"
#include "shootmarch.h"

namespace voxgi {

namespace {

// One family's sums in its axis order, (n,3) and (n,).
struct FamilySums {
    int m = 0;
    std::vector<double> acc, vis;
};

// What one line's walk reads and writes.
struct SortedLine {
    const LineSystem::Axis& ax;
    const float* pn;   // point and normal, 8 floats per record (axis order)
    const float* val;  // (axis order)
    const uint8_t* stand;
    const float* dh;
    double wgt;
    float eps;
    int K;
    bool transpose;
    FamilySums& sums;
    bool vis;
};

// Walk the records line[j0..j1) of one line in their order along +v: every
// B receives from the nearest facing F, and answers the facing F records
// before it that nothing hides (gather.cpp's pair_record).
void walk_line(const SortedLine& L, const int32_t* line, int64_t j0, int64_t j1,
               std::vector<Hit>& group) {
    // the line's F records so far, whether each was answered and by which B
    std::vector<int32_t> hp, hb;
    std::vector<char> ha;
    double* acc = L.sums.acc.data();
    double* vs = L.vis ? L.sums.vis.data() : nullptr;
    auto add = [&](int32_t to, int32_t from, double w) {  // to takes from's value
        const float* v = L.val + 3 * int64_t(L.transpose ? to : from);
        double* a = acc + 3 * int64_t(L.transpose ? from : to);
        a[0] += v[0] * w;
        a[1] += v[1] * w;
        a[2] += v[2] * w;
    };
    for (int64_t j = j0; j < j1;) {
        // the records of one voxel: same line and same x_m
        const int32_t x0 = L.ax.X[line[j]];
        int64_t ge = j + 1;
        while (ge < j1 && L.ax.X[line[ge]] == x0) ++ge;
        const int gn = static_cast<int>(ge - j);
        if (static_cast<int>(group.size()) < gn) group.resize(gn);
        Hit* g = group.data();
        for (int a = 0; a < gn; ++a) {
            const int32_t p = line[j + a];
            g[a] = Hit{p, dot3(L.pn + 8 * int64_t(p), L.dh), dot3(L.pn + 3 + 8 * int64_t(p), L.dh)};
        }
        if (gn > 1) sort_group(g, gn);
        for (int a = 0; a < gn; ++a) {
            const int32_t p = g[a].p;
            const float c = g[a].c;
            if (c > kTiny) {  // F: sends along +v; remember it
                hp.push_back(p);
                ha.push_back(0);
                hb.push_back(-1);
                continue;
            }
            if (c >= -kTiny) continue;
            // B: receives from the nearest facing F
            const float *pp = L.pn + 8 * int64_t(p), *np = L.pn + 3 + 8 * int64_t(p);
            const double cb = -double(c) * L.wgt;
            bool got = false;
            const bool sp = L.stand && L.stand[p];  // two stand-ins never pair
            int32_t wall = -1;  // the answerer of the newest answered facing F passed
            // F records passed over (at most K; a run in one plane counts once)
            int skipped = 0, steps = 0;
            int32_t passed = -1;
            for (int64_t h = int64_t(hp.size()) - 1; h >= 0 && skipped < L.K && steps < kMaxChain;
                 --h, ++steps) {
                const int32_t f = hp[h];
                const float *pf = L.pn + 8 * int64_t(f), *nf = L.pn + 3 + 8 * int64_t(f);
                if ((sp && L.stand[f]) || !facing(pf, nf, pp, np, L.eps)) {
                    skipped += !(passed >= 0 && same_plane(pf, nf, L.pn + 8 * int64_t(passed),
                                                           L.pn + 3 + 8 * int64_t(passed)));
                    passed = f;
                    continue;
                }
                if (!got) {
                    add(p, f, cb);
                    if (vs) vs[p] += cb;
                    got = true;
                }
                if (ha[h]) {  // it or its answerer hides the older F records
                    if (wall >= 0 || !L.ax.crossing[f]) break;
                    wall = hb[h];
                    continue;
                }
                if (wall >= 0 && hidden_behind(pf, L.pn + 8 * int64_t(wall),
                                               L.pn + 3 + 8 * int64_t(wall), L.eps))
                    break;
                // F receives (along -v) from the first B that faces it
                const double cf = double(dot3(nf, L.dh)) * L.wgt;
                add(f, p, cf);
                if (vs) vs[f] += cf;
                ha[h] = true;
                hb[h] = p;
            }
        }
        j = ge;
    }
}

}  // namespace

int64_t gather_sorted(const LineSystem& ls, const Family* fams, const int64_t* sel, int64_t nsel,
                      const float* val, double* out, double* vis, bool transpose,
                      const GatherOptions& opt, const StopCheck& stop) {
    if (opt.record) throw std::invalid_argument("the sorted walk does not record pairs");
    const uint8_t* stand_in = opt.stand_in;
    std::vector<float> valax[3];
    std::vector<uint8_t> sbax[3];
    for (int m = 0; m < 3; ++m) {
        ls.to_axis_order(m, val, valax[m]);
        if (!stand_in) continue;
        sbax[m].resize(ls.size());
        for (int64_t i = 0; i < ls.size(); ++i) sbax[m][i] = stand_in[ls.axis(m).order[i]] ? 1 : 0;
    }
    std::fill(out, out + 3 * ls.size(), 0.0);
    if (vis) std::fill(vis, vis + ls.size(), 0.0);
    const int threads = static_cast<int>(
        std::max<int64_t>(1, std::min<int64_t>(resolve_threads(opt.threads), nsel)));
    std::vector<int64_t> lines(threads, 0);
    InOrder<FamilySums> in_order;
    auto add_family = [&](FamilySums& s) {
        const int32_t* ord = ls.axis(s.m).order.data();
        for (int64_t i = 0; i < ls.size(); ++i) {
            for (int c = 0; c < 3; ++c) out[3 * int64_t(ord[i]) + c] += s.acc[3 * i + c];
            if (vis) vis[ord[i]] += s.vis[i];
        }
    };
    parallel_for(nsel, threads, stop, [&](int64_t k, int t) {
        const Family& F = fams[sel[k]];
        const LineFrame fr(F.v, ls.lo(), ls.hi());
        const LineSystem::Axis& ax = ls.axis(fr.m);
        FamilySums sums;
        sums.m = fr.m;
        sums.acc.assign(3 * ls.size(), 0.0);
        if (vis) sums.vis.assign(ls.size(), 0.0);
        float dh[3];
        unit_direction(F, dh);
        // keys in the axis order (x_m ascending), then a stable counting
        // sort: each line's records come out ordered along +v
        const int64_t nkeys = fr.nu * fr.nw;
        std::vector<uint32_t> key(ls.size()), cnt(nkeys + 1, 0);
        std::vector<int32_t> line(ls.size());
        for (int64_t i = 0; i < ls.size(); ++i) {
            key[i] = fr.key(ax.X[i] - fr.lo[fr.m], fr.yprime(ax.Y[i]), fr.zprime(ax.Z[i]));
            ++cnt[key[i] + 1];
        }
        for (int64_t q = 0; q < nkeys; ++q) cnt[q + 1] += cnt[q];
        // cnt[q] = start of line q; the scatter advances it to the line's end
        for (int64_t i = 0; i < ls.size(); ++i) line[cnt[key[i]]++] = static_cast<int32_t>(i);
        const SortedLine L{
            ax,        ax.pn.data(), valax[fr.m].data(), stand_in ? sbax[fr.m].data() : nullptr,
            dh,        F.weight,     ls.epsilon(),       ls.history(),
            transpose, sums,         vis != nullptr};
        std::vector<Hit> group;
        int64_t start = 0;
        for (int64_t q = 0; q < nkeys; ++q) {
            const int64_t end = cnt[q];
            if (end - start >= 2) {
                ++lines[t];
                walk_line(L, line.data(), start, end, group);
            }
            start = end;
        }
        in_order.finish(k, std::move(sums), add_family);
    });
    int64_t total = 0;
    for (auto x : lines) total += x;
    return total;
}

namespace {

// The sender-side deposit: the ray's power val[e] * cos_e * weight *
// send_scale[e], shared by its receivers in proportion to recv_area * cos_r.
struct SenderSide {
    static constexpr bool kKeepShadowed = true;
    const double *send_scale, *recv_area;
    bool operator()(const Ray& r, const Family&, const float* ve, const std::vector<RayHit>& recv,
                    std::vector<Deposit>& out) const {
        double tot = 0.0;
        for (const RayHit& q : recv) tot += recv_area[q.p] * q.c;
        if (!(tot > 0)) return false;
        const double pw = r.ce * send_scale[r.e] / tot;
        for (const RayHit& q : recv) {
            const double share = pw * recv_area[q.p] * q.c;
            out.push_back(Deposit{q.p, {ve[0] * share, ve[1] * share, ve[2] * share}});
        }
        return true;
    }
};

}  // namespace

ShootCount shoot_sender_side(const LineSystem& ls, const int32_t* emit, int64_t ne,
                             const Family* fams, int64_t nf, const float* val,
                             const double* send_scale, const double* recv_area, double* hd,
                             double* unfound, const ShootOptions& opt, const StopCheck& stop) {
    if (opt.coverage || opt.object)
        throw std::invalid_argument(
            "coverage and silhouettes: only with the receiver-side deposit");
    return shoot_march(ls, emit, ne, fams, nf, val, hd, unfound, opt,
                       SenderSide{send_scale, recv_area}, stop);
}

}  // namespace voxgi
