// The records of a solve prepared for discrete-line propagation (Chatelier &
// Malgouyres 2006; Piwowar & Malgouyres 2008): line keys in O(1), one
// lexicographic order of the records per main axis, and visibility along
// each line by the facing rule (docs/design.md §4). This is the prepared
// records and their normalisation; the passes over them are concepts of
// their own, each reading a LineSystem: gather.h (the one-pass walk),
// pairtable.h (recorded pairs and their replay), shoot.h (direct light) and
// reference.h (reference and adjoint variants for the tests).
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>
#include <mutex>
#include <vector>

#include "lineframe.h"
#include "util/parallel.h"

namespace voxgi {

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

    // Key of every record for family v (tests: each key is one naive line).
    void keys(const int32_t v[3], uint32_t* out) const;

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

    float epsilon() const { return eps_; }  // the facing-rule margin, voxel units
    int history() const { return hist_; }   // F records remembered per line
    const Axis& axis(int m) const { return ax_[m]; }
    // (n,3) normals and surface points in the global record order
    const float* normal() const { return normal_; }
    const float* point() const { return point_; }
    // val (n,3) global order -> out (n,3) in main axis m's order
    void to_axis_order(int m, const float* val, std::vector<float>& out) const;

    // The shooting's voxel index: one occupancy bit per voxel of the box
    // (built on the first call), the occupied voxels before each 64-bit word,
    // and each occupied voxel's records, axis(0).order[voxel_start()[k] ..
    // voxel_start()[k + 1]).
    void build_occupancy() const;
    const uint64_t* occupancy() const { return occ_.data(); }
    const int32_t* occupancy_rank() const { return occ_rank_.data(); }
    const int32_t* voxel_start() const { return vstart_.data(); }
    // a voxel's index in the box, x-major
    int64_t linear(int32_t x, int32_t y, int32_t z) const;

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
};

}  // namespace voxgi
