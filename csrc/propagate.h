// Linear-complexity discrete-line propagation (Chatelier & Malgouyres 2006;
// Piwowar & Malgouyres 2008): line keys in O(1), one lexicographic order of
// the records per main axis, a stable counting sort per direction family,
// and visibility along each line by the facing rule of DESIGN-NOTES §4.
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>
#include <cstring>
#include <mutex>
#include <vector>

#include "common.h"

namespace voxgi {

// A direction family: the integer vector v and its opposite -v share one
// partition of space into naive discrete lines. `v` is stored with its main
// component (the largest |v_i|, lowest i on ties) positive.
struct Family {
    int32_t v[3];
    double weight;  // solid angle of each of +v and -v, divided by pi
};

// The naive-line key of voxel `ijk` for family `v` (main component > 0),
// relative to the box [lo, hi] (inclusive voxel bounds): two integers (u, w)
// packed as u * nw + w with 0 <= key < nu * nw. Exposed for tests.
struct LineFrame {
    int m, o1, o2;       // main axis and the two others (increasing order)
    int32_t A, B, C;     // |v| components along m, o1, o2 (A >= B, C >= 0)
    bool pos1, pos2;     // sign of v along o1, o2 (true: >= 0)
    int32_t lo[3], hi[3];
    int64_t XmA;         // multiple of A >= hi[m] - lo[m]: keeps numerators >= 0
    int64_t nu, nw;      // key ranges
    uint64_t magic;      // ceil(2^32 / A): exact division for numerators < 2^32 / A
    LineFrame(const int32_t v[3], const int32_t lo_[3], const int32_t hi_[3]);
    inline int64_t yprime(int32_t y) const { return pos1 ? y - lo[o1] : hi[o1] - y; }
    inline int64_t zprime(int32_t z) const { return pos2 ? z - lo[o2] : hi[o2] - z; }
    inline uint32_t div(uint64_t num) const { return static_cast<uint32_t>((num * magic) >> 32); }
    // key from main-axis-relative coordinates X' = x_m - lo[m], Y', Z':
    // key = u(X', Y') * nw + w(X', Z') (the one-pass walk forms the same key
    // from a constant per slab; see LineSystem::gather)
    inline uint32_t key(int64_t Xp, int64_t Yp, int64_t Zp) const {
        const uint64_t h = static_cast<uint64_t>(A / 2);
        const uint64_t u = div(static_cast<uint64_t>(A * Yp + B * (XmA - Xp)) + h);
        const uint64_t w = div(static_cast<uint64_t>(A * Zp + C * (XmA - Xp)) + h);
        return static_cast<uint32_t>(u * static_cast<uint64_t>(nw) + w);
    }
};

// The pairs one gathering pass over a direction set found, kept so that the
// later iterations of a solve replay them instead of walking the lines again
// (visibility does not change between iterations). For each main axis m: the
// set's families of axis m, and record by record in axis-m order the axis-m
// position + 1 of the record each of those families pairs it with (0: none),
// 3 bytes per record and family (little-endian), in tiles of 16 families (a
// 48-byte row per record and tile). Filled by LineSystem::gather (record),
// read by LineSystem::gather_recorded.
struct PairTable {
    static constexpr int kTile = 16;   // columns per tile
    static constexpr int kEntry = 3;   // bytes per entry
    static constexpr int kRow = kTile * kEntry;  // bytes per record and tile (a multiple of 16)
    static constexpr int64_t kMaxRecords = (int64_t(1) << 24) - 2;  // position + 1 fits 3 bytes
    // entry `lane` of a row (reads 4 bytes: a block has slack after its last row)
    static inline uint32_t entry(const uint8_t *row, int lane) {
        uint32_t x;
        std::memcpy(&x, row + kEntry * lane, 4);
        return x & 0xFFFFFFu;
    }
    int64_t n = 0;        // records
    int64_t nfam = 0;     // families of the set
    bool with_stand_in = false;
    std::vector<int32_t> slot;       // family -> its column in its axis's table
    std::vector<int32_t> fam_axis;   // family -> main axis
    int64_t cols[3] = {0, 0, 0};     // axis m -> how many of the set's families it has
    std::vector<int32_t> vec;        // every family's vector, 3 per family (checked on use)
    std::vector<float> dir;          // unit direction of every family, 3 per family
    std::vector<double> weight;      // every family's weight
    struct Block {                   // anonymous memory: zero pages come free from the OS
        uint8_t *p = nullptr;
        size_t size = 0;
        Block() = default;
        Block(const Block &) = delete;
        Block &operator=(const Block &) = delete;
        Block(Block &&o) noexcept : p(o.p), size(o.size) { o.p = nullptr; o.size = 0; }
        Block &operator=(Block &&o) noexcept;
        ~Block();
        void allocate(size_t bytes);  // zero bytes (and kSlack more)
        static constexpr size_t kSlack = 16;
        void release();
    };
    // axis m: tiles of kTile columns; tile t's row for the record at axis-m
    // position p is snd[m].p[(t * n + p) * kRow ...]
    Block snd[3];
    std::vector<uint8_t> filled;     // family -> recorded yet
    size_t bytes() const { return snd[0].size + snd[1].size + snd[2].size; }
};

// The records of a solve, prepared once: bounding box, one lexicographic
// order per main axis (counting sort), the records' coordinates, normals and
// surface points stored in each order (so that a family's pass streams
// through memory), and a voxel -> records index for shooting.
class LineSystem {
public:
    // ijk (n,3) voxel coordinates; normal (n,3) unit; point (n,3) a point of
    // the surface in voxel units (voxel ijk spans [ijk, ijk+1]); epsilon the
    // facing-rule margin in voxel units; history the number of F records
    // remembered per line (1..32; the shooting keeps only the first and the
    // latest of a run of F records in one plane, so a face the line runs
    // along takes two places, not one a voxel).
    LineSystem(int64_t n, const int32_t *ijk, const float *normal, const float *point,
               float epsilon, int history);

    int64_t size() const { return n_; }

    // Raw sum S(n) = sum over families, both signs, of max(0, n.s) * weight
    // for every record (the hemisphere's cos-weighted solid angle / pi).
    void normalisation(const Family *fams, int64_t nf, double *S, int threads,
                       const StopCheck &stop) const;

    // Gathering over the families `fams[sel[k]]` (k < nsel): for every pair
    // of mutually visible records along a line, out[x] += val[partner] *
    // cos_x * weight (RGB, double, not yet divided by S). vis (nullable):
    // vis[x] += cos_x * weight for every direction in which x found a
    // partner. out and vis are overwritten. Returns the number of lines
    // walked (lines with >= 2 records); lines with one record are skipped.
    // onepass: one pass in x_m order with a per-line state table (default);
    // otherwise a stable counting sort by line key, then a walk of each line.
    // stand_in (nullable, (n,), global order): nonzero for the back records
    // of closed objects, which send their front twin's value and only stand
    // in for it where a line clips the object's band. Two stand-ins never
    // pair: a stand-in B looks past the stand-in F records of its line
    // (neither receives from the other, the F is not marked answered, so it
    // does not occlude the older F records from the receivers further on).
    // transpose: the transposed operator, out[partner] += val[x] * cos_x *
    // weight for the same pairs (x's weight, the partner receives): for
    // every record the power it delivers per unit sent, with val = area / S
    // (the conservative scaling, DESIGN-NOTES §5). vis is unchanged.
    int64_t gather(const Family *fams, const int64_t *sel, int64_t nsel, const float *val,
                   double *out, double *vis, int threads, const StopCheck &stop,
                   bool onepass = true, const uint8_t *stand_in = nullptr,
                   bool transpose = false, PairTable *record = nullptr) const;

    // Record the pairs of the families gathered by `gather` into `table`
    // (made by make_pair_table for the same family array, and the same
    // stand-in flags every time): pass it as `record` to any gather call.
    PairTable make_pair_table(const Family *fams, int64_t nf, bool with_stand_in) const;

    // The gathering pass over the recorded families `sel` (every one of them
    // recorded), from the table instead of the lines: the same pairs, the
    // same weights, the sums added per record in family order (results
    // equal gather's to float rounding, and do not depend on `threads`).
    void gather_recorded(const PairTable &table, const int64_t *sel, int64_t nsel, const float *val,
                         double *out, double *vis, int threads, const StopCheck &stop) const;

    // Shooting from the emitter records `emit[0..ne)` along every direction
    // +v and -v of every family (with n_e.s > 0): an integer march along the
    // same naive line through the occupancy bitset to the records whose
    // nearest facing sender is e. hd[r] += val[e] * cos_r * weight (RGB,
    // double, overwritten). unfound[k] = sum of cos_e * weight over the rays
    // of emitter k that met no receiver (sender side, overwritten). Returns
    // the number of rays (emitter x direction with n_e.s > 0) and, in
    // *steps, the voxels visited.
    // send_scale, recv_area (both non-null, (n,)): deposit on the sender
    // side instead: a ray of e carries val[e] * cos_e * weight *
    // send_scale[e] (send_scale = area / S: the ray's power) and the
    // receivers of the ray share it in proportion to recv_area[r] * cos_r;
    // hd then holds power (divide by the area for irradiance), and the
    // direct light conserves energy exactly, at the price of per-record
    // aliasing (which voxel catches a ray is not which surface is there).
    // coverage (nullable, (n,), receiver-side mode only): the record's
    // surface area in voxel units. A ray of e then stands for the share
    // alpha = coverage[e] |n_e.d| / |d_m| of its line's cross-section (|d_m|
    // in voxel units: one naive line per |d_m| of area across d) instead of
    // all of it, and F records that are not in front of e's plane (by more
    // than epsilon: e's own sheet, e.g. the rest of a flat lamp seen edge-on)
    // do not occlude it: each of them sends its own share. A thin emitter
    // seen edge-on then sends what its area projects, not a whole line per
    // voxel of its band. Meant for flat emitters: on a curved sheet the
    // neighbours in front of e's plane would still occlude e's share. A
    // negative coverage[e] keeps the whole-line rule for e.
    // stand_in (nullable, (n,)): as for gather; a stand-in receiver's
    // sender is the nearest facing F that is not a stand-in (so a stand-in
    // emitter deposits nothing on a stand-in receiver).
    // object, sil_area, back (all null or all (n,), receiver-side mode only):
    // silhouettes. A band of receivers of one object in consecutive steps
    // covers sum sil_area[r] |n_r.d| / |d_m| of the line (sil_area: area in
    // voxel units; negative: the record's object is never passed, e.g. an
    // emitting one, whose exit face already shoots its whole line). If a
    // receiver's voxel holds another face of the object that the line leaves
    // (F, normals 60-154 degrees apart, convex edge) and the line then meets
    // an F record of that object within one step, the line only grazed it:
    // the share T (1 - band) goes on, the object's F and back records (and the
    // front B records of the grazed face, within 60 degrees of its normal,
    // while the line still runs along it) no longer stop it, and later
    // receivers take T times their usual deposit; another face of the object
    // that the line runs towards (a lit side below a grazed top edge) is such
    // a receiver.
    int64_t shoot(const int32_t *emit, int64_t ne, const Family *fams, int64_t nf,
                  const float *val, double *hd, double *unfound, int threads,
                  const StopCheck &stop, int64_t *steps, const double *send_scale = nullptr,
                  const double *recv_area = nullptr, const double *coverage = nullptr,
                  const uint8_t *stand_in = nullptr, const int32_t *object = nullptr,
                  const double *sil_area = nullptr, const uint8_t *back = nullptr) const;

    // Key of every record for family v (tests: each key is one naive line).
    void keys(const int32_t v[3], uint32_t *out) const;

    const int32_t *lo() const { return lo_; }
    const int32_t *hi() const { return hi_; }

private:
    struct Axis {
        std::vector<int32_t> order;  // record index at each position
        std::vector<int32_t> X, Y, Z;  // coordinates along m, o1, o2
        std::vector<float> nrm, pt;    // (n,3) world-axis normal and point, in this order
        std::vector<float> pn;         // (n,8) point then normal: one 32-byte line per record
        // The voxels in this order: voxel k holds records gstart[k] ..
        // gstart[k+1]) (one record, or a closed object's front record and
        // its back twin, mostly); gflag[k]: kTwin where it holds two records
        // with one surface point and opposite normals (a front record and
        // its back twin), whose order along any d is the sign of one dot
        // product. Slab s (one x_m) holds voxels gslab[s] .. gslab[s+1]).
        // Found once, so a family's walk does not compare coordinates.
        static constexpr uint8_t kTwin = 2;
        std::vector<int32_t> gstart;
        std::vector<uint8_t> gflag;
        std::vector<int32_t> gslab;
        int gmax = 0;  // most records in one voxel
    };
    int64_t n_;
    float eps_;
    int hist_;
    int32_t lo_[3], hi_[3];
    Axis ax_[3];
    // shooting: occupancy bitset over the box and the records of each voxel
    mutable std::vector<uint64_t> occ_;
    mutable std::vector<int32_t> occ_rank_;  // occupied voxels before each word of occ_: a voxel's slot in vkey_ in O(1)
    mutable std::once_flag occ_once_;
    void build_occupancy() const;
    std::vector<int64_t> vkey_;    // sorted linear keys of occupied voxels (one per voxel)
    std::vector<int32_t> vstart_;  // records of voxel k: ax_[0].order[vstart_[k] .. vstart_[k+1])
    std::vector<float> own_normal_, own_point_;  // copies in the global record order
    const float *normal_, *point_;
    int64_t linear(int32_t x, int32_t y, int32_t z) const;
    // val (n,3) global order -> out (n,3) in main axis m's order
    void to_axis_order(int m, const float *val, std::vector<float> &out) const;
};

}  // namespace voxgi
