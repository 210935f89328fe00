// The gathering pass over a line system: every line of every family walked
// once, in order, each record paired with the nearest facing records it sees
// (docs/design.md §4). Implemented in gather.cpp. No pybind11 here.
#pragma once

#include <cstdint>

#include "linesystem.h"
#include "pairtable.h"

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

// Gathering over the families `fams[sel[k]]` (k < nsel): for every pair of
// mutually visible records along a line, out[x] += val[partner] * cos_x *
// weight (RGB, double, not yet divided by S). vis (nullable): vis[x] +=
// cos_x * weight for every direction in which x found a partner. out and vis
// are overwritten; they do not depend on the number of threads. Returns the
// number of lines walked (lines with >= 2 records); lines with one record
// are skipped.
int64_t gather(const LineSystem& ls, const Family* fams, const int64_t* sel, int64_t nsel,
               const float* val, double* out, double* vis, const GatherOptions& opt,
               const StopCheck& stop);

}  // namespace voxgi
