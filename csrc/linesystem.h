// The records of a solve prepared for discrete-line propagation (Chatelier &
// Malgouyres 2006; Piwowar & Malgouyres 2008): line keys in O(1), one
// lexicographic order of the records per main axis, and visibility along
// each line by the facing rule (docs/design.md §4). The kernels live in
// linesystem.cpp (preparation, normalisation), gather.cpp (the one-pass
// walk), pairtable.cpp (recorded pairs), shoot.cpp (direct light) and
// reference.cpp (reference and adjoint variants for the tests).
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>
#include <mutex>
#include <vector>

#include "lineframe.h"
#include "pairtable.h"
#include "util/parallel.h"

namespace voxgi {

// A gathering pass's inputs besides the families and values.
struct GatherOptions {
    // (n,) global order, nullable: nonzero for the back records of closed
    // objects, which send their front twin's value and only stand in for it
    // where a line clips the object's band. Two stand-ins never pair: a
    // stand-in B looks past the stand-in F records of its line (neither
    // receives from the other, the F is not marked answered, so it does not
    // occlude the older F records from the receivers further on).
    const uint8_t* stand_in = nullptr;
    // nullable: also record the pairs found (a table from make_pair_table
    // for the same family array and the same stand-in flags every time)
    PairTable* record = nullptr;
    int threads = 0;  // 0: all hardware threads
};

// The shooting's inputs besides the emitters, families and values (all
// nullable, (n,) global order; docs/design.md §5).
struct ShootOptions {
    // The record's surface area in voxel units. A ray of e then stands for
    // the share alpha = coverage[e] |n_e.d| / |d_m| of its line's
    // cross-section (|d_m| in voxel units: one naive line per |d_m| of area
    // across d) instead of all of it, and F records that are not in front of
    // e's plane (by more than epsilon: e's own sheet, e.g. the rest of a flat
    // lamp seen edge-on) do not occlude it: each of them sends its own share.
    // A thin emitter seen edge-on then sends what its area projects, not a
    // whole line per voxel of its band. Meant for flat emitters: on a curved
    // sheet the neighbours in front of e's plane would still occlude e's
    // share. A negative coverage[e] keeps the whole-line rule for e.
    const double* coverage = nullptr;
    // As for GatherOptions; a stand-in receiver's sender is the nearest
    // facing F that is not a stand-in (so a stand-in emitter deposits
    // nothing on a stand-in receiver).
    const uint8_t* stand_in = nullptr;
    // Silhouettes (all three or none). A band of receivers of one object in
    // consecutive steps covers sum sil_area[r] |n_r.d| / |d_m| of the line
    // (sil_area: area in voxel units; negative: the record's object is never
    // passed, e.g. an emitting one, whose exit face already shoots its whole
    // line). If a receiver's voxel holds another face of the object that the
    // line leaves (F, normals 60-154 degrees apart, convex edge) and the line
    // then meets an F record of that object within one step, the line only
    // grazed it: the share T (1 - band) goes on, the object's F and back
    // records (and the front B records of the grazed face, within 60 degrees
    // of its normal, while the line still runs along it) do not stop it,
    // and later receivers take T times their usual deposit; another face of
    // the object that the line runs towards (a lit side below a grazed top
    // edge) is such a receiver.
    const int32_t* object = nullptr;
    const double* sil_area = nullptr;
    const uint8_t* back = nullptr;
    int threads = 0;  // 0: all hardware threads
};

struct ShootCount {
    int64_t rays = 0;   // emitter x direction with n_e.s > 0
    int64_t steps = 0;  // voxels visited
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
    LineSystem(int64_t n, const int32_t* ijk, const float* normal, const float* point,
               float epsilon, int history);

    int64_t size() const { return n_; }
    const int32_t* lo() const { return lo_; }
    const int32_t* hi() const { return hi_; }

    // Raw sum S(n) = sum over families, both signs, of max(0, n.s) * weight
    // for every record (the hemisphere's cos-weighted solid angle / pi).
    void normalisation(const Family* fams, int64_t nf, double* S, int threads,
                       const StopCheck& stop) const;

    // Gathering over the families `fams[sel[k]]` (k < nsel): for every pair
    // of mutually visible records along a line, out[x] += val[partner] *
    // cos_x * weight (RGB, double, not yet divided by S). vis (nullable):
    // vis[x] += cos_x * weight for every direction in which x found a
    // partner. out and vis are overwritten; they do not depend on the number
    // of threads. Returns the number of lines walked (lines with >= 2
    // records); lines with one record are skipped.
    int64_t gather(const Family* fams, const int64_t* sel, int64_t nsel, const float* val,
                   double* out, double* vis, const GatherOptions& opt, const StopCheck& stop) const;

    // An empty table for the pairs of these families (zero pages: memory is
    // used as the pairs are written).
    PairTable make_pair_table(const Family* fams, int64_t nf, bool with_stand_in) const;

    // The gathering pass over the recorded families `sel` (every one of them
    // recorded), from the table instead of the lines: the same pairs, the
    // same weights, the sums added per record in family order (results
    // equal gather's to float rounding, and do not depend on `threads`).
    void gather_recorded(const PairTable& table, const int64_t* sel, int64_t nsel, const float* val,
                         double* out, double* vis, int threads, const StopCheck& stop) const;

    // Shooting from the emitter records `emit[0..ne)` along every direction
    // +v and -v of every family (with n_e.s > 0): an integer march along the
    // same naive line through the occupancy bitset to the records whose
    // nearest facing sender is e. hd[r] += val[e] * cos_r * weight (RGB,
    // double, overwritten; added in emitter order, whatever the threads).
    // unfound[k] = sum of cos_e * weight over the rays of emitter k that met
    // no receiver (sender side, overwritten).
    ShootCount shoot(const int32_t* emit, int64_t ne, const Family* fams, int64_t nf,
                     const float* val, double* hd, double* unfound, const ShootOptions& opt,
                     const StopCheck& stop) const;

    // Key of every record for family v (tests: each key is one naive line).
    void keys(const int32_t v[3], uint32_t* out) const;

    // ------------------------------------------------ reference.cpp (tests)
    // The gathering by a stable counting sort of every family's records by
    // line key, then a walk of each line: the reference the one-pass walk is
    // checked against. transpose: the transposed operator, out[partner] +=
    // val[x] * cos_x * weight for the same pairs (x's weight, the partner
    // receives): with val = area / S, the power each record delivers per
    // unit sent (docs/design.md §5). vis is unchanged by transpose.
    // (opt.record must be null.)
    int64_t gather_sorted(const Family* fams, const int64_t* sel, int64_t nsel, const float* val,
                          double* out, double* vis, bool transpose, const GatherOptions& opt,
                          const StopCheck& stop) const;
    // The shooting with the deposit on the sender side: a ray of e carries
    // val[e] * cos_e * weight * send_scale[e] (send_scale = area / S: the
    // ray's power) and its receivers share it in proportion to recv_area[r]
    // * cos_r; hd then holds power, and the direct light conserves energy
    // exactly, at the price of per-record aliasing (which voxel catches a ray
    // is not which surface is there).
    // (opt: stand-ins and threads only.)
    ShootCount shoot_sender_side(const int32_t* emit, int64_t ne, const Family* fams, int64_t nf,
                                 const float* val, const double* send_scale,
                                 const double* recv_area, double* hd, double* unfound,
                                 const ShootOptions& opt, const StopCheck& stop) const;

    // The records in main axis m's order (the walks and the march read them).
    struct Axis {
        std::vector<int32_t> order;    // record index at each position
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
        // per position: 1 where the record's voxel holds records of more than
        // one plane (surfaces meet or cross in it)
        std::vector<uint8_t> crossing;
        std::vector<int32_t> gslab;
        int gmax = 0;  // most records in one voxel
    };

   private:
    int64_t n_;
    float eps_;
    int hist_;
    int32_t lo_[3], hi_[3];
    Axis ax_[3];
    // shooting: occupancy bitset over the box and the records of each voxel
    mutable std::vector<uint64_t> occ_;
    // occupied voxels before each word of occ_: a voxel's slot in vkey_ in O(1)
    mutable std::vector<int32_t> occ_rank_;
    mutable std::once_flag occ_once_;
    std::vector<int64_t> vkey_;    // sorted linear keys of occupied voxels (one per voxel)
    std::vector<int32_t> vstart_;  // records of voxel k: ax_[0].order[vstart_[k] .. vstart_[k+1])
    std::vector<float> own_normal_, own_point_;  // copies in the global record order
    const float *normal_, *point_;

    void sort_axis(int m, const int32_t* ijk);
    void find_voxels(int m);
    void build_occupancy() const;
    int64_t linear(int32_t x, int32_t y, int32_t z) const;
    // val (n,3) global order -> out (n,3) in main axis m's order
    void to_axis_order(int m, const float* val, std::vector<float>& out) const;
    void check_record(const Family* fams, const int64_t* sel, int64_t nsel,
                      const GatherOptions& opt) const;
    template <class Deposit>
    ShootCount march(const int32_t* emit, int64_t ne, const Family* fams, int64_t nf,
                     const float* val, double* hd, double* unfound, const ShootOptions& opt,
                     const Deposit& deposit, const StopCheck& stop) const;
    friend class ShootMarch;
};

}  // namespace voxgi
