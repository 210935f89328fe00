// Recording the pairs of a gathering pass and replaying them
// (docs/design.md §4).
#include "pairtable.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "linesystem.h"
#include "util/simd.h"

namespace voxgi {

void PairTable::write_tile(int m, int64_t tile, uint32_t lanes, int32_t* buf) {
    constexpr int kT = kTile, kE = kEntry, kR = kRow;
    uint8_t* blk = snd[m].data() + tile * n * kR;
    if (lanes != (1u << kT) - 1) {  // some columns: entry by entry
        for (int64_t p = 0; p < n; ++p) {
            uint8_t* row = blk + p * kR;
            for (int lane = 0; lane < kT; ++lane)
                if (lanes >> lane & 1u) {
                    const uint32_t x = static_cast<uint32_t>(buf[int64_t(lane) * n + p]);
                    std::memcpy(row + kE * lane, &x, kE);  // little-endian: the low 3 bytes
                    buf[int64_t(lane) * n + p] = 0;
                }
        }
        return;
    }
    for (int64_t p = 0; p < n; ++p) {
        // the row packed in order (each 4-byte write's top byte is the next
        // entry's first, or spare past the row's end), then streamed out:
        // nothing reads it back in this pass (rows are 16-byte aligned)
        alignas(16) uint8_t tmp[kR + 16];
        for (int lane = 0; lane < kT; ++lane) {
            const uint32_t x = static_cast<uint32_t>(buf[int64_t(lane) * n + p]);
            std::memcpy(tmp + kE * lane, &x, 4);
            buf[int64_t(lane) * n + p] = 0;
        }
        stream_copy(blk + p * kR, tmp, kR);
    }
    store_fence();
}

PairTable make_pair_table(const LineSystem& ls, const Family* fams, int64_t nf,
                          bool with_stand_in) {
    if (ls.size() > PairTable::kMaxRecords)
        throw std::invalid_argument("pair table: " + std::to_string(ls.size()) +
                                    " records, at most " + std::to_string(PairTable::kMaxRecords) +
                                    " fit its 3-byte entries");
    PairTable t;
    t.n = ls.size();
    t.nfam = nf;
    t.with_stand_in = with_stand_in;
    t.slot.resize(nf);
    t.fam_axis.resize(nf);
    t.vec.resize(3 * nf);
    t.dir.resize(3 * nf);
    t.weight.resize(nf);
    t.filled.assign(nf, 0);
    for (int64_t f = 0; f < nf; ++f) {
        LineFrame fr(fams[f].v, ls.lo(), ls.hi());  // validates the vector
        t.fam_axis[f] = fr.m;
        t.slot[f] = static_cast<int32_t>(t.cols[fr.m]++);
        unit_direction(fams[f], &t.dir[3 * f]);
        for (int c = 0; c < 3; ++c) t.vec[3 * f + c] = fams[f].v[c];
        t.weight[f] = fams[f].weight;
    }
    for (int m = 0; m < 3; ++m) {
        const size_t tiles =
            (static_cast<size_t>(t.cols[m]) + PairTable::kTile - 1) / PairTable::kTile;
        const size_t size = static_cast<size_t>(ls.size()) * tiles * PairTable::kRow;
        if (size == 0) continue;
        t.snd[m].allocate(size);
    }
    return t;
}

namespace {

// The selected columns of one axis in column order, grouped by tile: each
// column's lane, direction (one array per component) and weight.
struct AxisColumns {
    std::vector<int32_t> lane;
    std::vector<float> dx, dy, dz;
    std::vector<double> wt;
    std::vector<int64_t> tile,
        tile_first;  // tiles with a selected column, where their columns start
    size_t size() const { return lane.size(); }
};

void select_columns(const PairTable& tab, const int64_t* sel, int64_t nsel, AxisColumns cols[3]) {
    std::vector<int64_t> fam[3];
    for (int64_t k = 0; k < nsel; ++k) {
        const int64_t f = sel[k];
        if (f < 0 || f >= tab.nfam) throw std::invalid_argument("family outside the pair table");
        if (!tab.filled[f])
            throw std::invalid_argument("family " + std::to_string(f) + " not recorded");
        fam[tab.fam_axis[f]].push_back(f);
    }
    for (int m = 0; m < 3; ++m) {
        std::vector<int64_t>& fm = fam[m];
        std::stable_sort(fm.begin(), fm.end(),
                         [&](int64_t a, int64_t b) { return tab.slot[a] < tab.slot[b]; });
        AxisColumns& ac = cols[m];
        for (int64_t f : fm) {
            const int32_t c = tab.slot[f];
            ac.lane.push_back(c % PairTable::kTile);
            ac.dx.push_back(tab.dir[3 * f]);
            ac.dy.push_back(tab.dir[3 * f + 1]);
            ac.dz.push_back(tab.dir[3 * f + 2]);
            ac.wt.push_back(tab.weight[f]);
            if (ac.tile.empty() || ac.tile.back() != c / PairTable::kTile) {
                ac.tile.push_back(c / PairTable::kTile);
                ac.tile_first.push_back(static_cast<int64_t>(ac.lane.size()) - 1);
            }
        }
        ac.tile_first.push_back(static_cast<int64_t>(ac.lane.size()));
    }
}

constexpr int64_t kReplayChunk = 1024;  // records whose sums stay in L1 while the tiles stream by

// One tile's selected columns for records [b, e): acc[p - b] += val[sender]
// * |n.d| * weight (acc[.][3] sums the weights: v holds 1 there).
void replay_tile(const uint8_t* blk, const AxisColumns& ac, size_t ti, const float* nrm,
                 const float* v, int64_t b, int64_t e, double (*acc)[4]) {
    constexpr int kT = PairTable::kTile;
    const int64_t q0 = ac.tile_first[ti], q1 = ac.tile_first[ti + 1];
    const int nq = static_cast<int>(q1 - q0);  // at most kT
    const float *tx = ac.dx.data() + q0, *ty = ac.dy.data() + q0, *tz = ac.dz.data() + q0;
    const int32_t* tl = ac.lane.data() + q0;
    const double* tw = ac.wt.data() + q0;
    for (int64_t p = b; p < e; ++p) {
        const uint8_t* row = blk + p * PairTable::kRow;
        const float n0 = nrm[3 * p], n1 = nrm[3 * p + 1], n2 = nrm[3 * p + 2];
        double* a = acc[p - b];
        // the tile's |n.d| at once (a loop the compiler vectorises; each lane
        // the same float operations in the same order)
        alignas(16) float cs[kT];
        for (int q = 0; q < nq; ++q) cs[q] = std::abs(n0 * tx[q] + n1 * ty[q] + n2 * tz[q]);
        for (int q = 0; q < nq; ++q) {
            const uint32_t s = PairTable::entry(row, tl[q]);
            if (s == 0) continue;
            madd4(a, v + 4 * int64_t(s - 1), double(cs[q]) * tw[q]);
        }
    }
}

}  // namespace

void gather_recorded(const LineSystem& ls, const PairTable& tab, const int64_t* sel, int64_t nsel,
                     const float* val, double* out, double* vis, int threads,
                     const StopCheck& stop) {
    if (tab.n != ls.size()) throw std::invalid_argument("pair table made for another line system");
    AxisColumns cols[3];
    select_columns(tab, sel, nsel, cols);
    std::fill(out, out + 3 * ls.size(), 0.0);
    if (vis) std::fill(vis, vis + ls.size(), 0.0);
    threads = resolve_threads(threads);
    std::vector<float> va(4 * ls.size());
    for (int m = 0; m < 3; ++m) {
        const AxisColumns& ac = cols[m];
        if (ac.size() == 0) continue;
        // values in this axis's order (the senders are axis-order positions),
        // 16 bytes a record: the value, then 1 (so that one pair of packed
        // multiply-adds also sums the weight)
        const int32_t* ord = ls.axis(m).order.data();
        for (int64_t i = 0; i < ls.size(); ++i) {
            const int64_t r = ord[i];
            va[4 * i] = val[3 * r];
            va[4 * i + 1] = val[3 * r + 1];
            va[4 * i + 2] = val[3 * r + 2];
            va[4 * i + 3] = 1.0f;
        }
        const uint8_t* base = tab.snd[m].data();
        const float* nrm = ls.axis(m).nrm.data();
        // A chunk of records at a time, tile after tile: the table streams
        // (one 48-byte row per record and tile), and every record's sum is
        // added in column order by one task (no dependence on threads).
        parallel_for(
            (ls.size() + kReplayChunk - 1) / kReplayChunk, threads, stop, [&](int64_t task, int) {
                const int64_t b = task * kReplayChunk, e = std::min(ls.size(), b + kReplayChunk);
                alignas(16) double acc[kReplayChunk][4];
                for (int64_t p = b; p < e; ++p)
                    for (int c = 0; c < 4; ++c) acc[p - b][c] = 0.0;
                for (size_t ti = 0; ti < ac.tile.size(); ++ti)
                    replay_tile(base + ac.tile[ti] * ls.size() * PairTable::kRow, ac, ti, nrm,
                                va.data(), b, e, acc);
                for (int64_t p = b; p < e; ++p) {
                    const int64_t r = ord[p];
                    out[3 * r] += acc[p - b][0];
                    out[3 * r + 1] += acc[p - b][1];
                    out[3 * r + 2] += acc[p - b][2];
                    if (vis) vis[r] += acc[p - b][3];
                }
            });
    }
}

}  // namespace voxgi
