// Direct light by shooting over a line system: integer discrete rays from
// the emitter records to the receivers they reach first (docs/design.md §5).
// Implemented in shoot.cpp (the march itself: shootmarch.h). No pybind11 here.
#pragma once

#include <cstdint>

#include "linesystem.h"

namespace voxgi {

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

// Shooting from the emitter records `emit[0..ne)` along every direction +v
// and -v of every family (with n_e.s > 0): an integer march along the same
// naive line through the occupancy bitset to the records whose nearest
// facing sender is e. hd[r] += val[e] * cos_r * weight (RGB, double,
// overwritten; added in emitter order, whatever the threads). unfound[k] =
// sum of cos_e * weight over the rays of emitter k that met no receiver
// (sender side, overwritten).
ShootCount shoot(const LineSystem& ls, const int32_t* emit, int64_t ne, const Family* fams,
                 int64_t nf, const float* val, double* hd, double* unfound, const ShootOptions& opt,
                 const StopCheck& stop);

}  // namespace voxgi
