// The pairs one gathering pass over a direction set found, kept so that the
// later iterations of a solve replay them instead of walking the lines again
// (visibility does not change between iterations; docs/design.md §4), and
// the replay. Implemented in pairtable.cpp.
#pragma once

#include <cstdint>
#include <cstring>
#include <vector>

#include "linesystem.h"
#include "util/memory.h"

namespace voxgi {

// For each main axis m: the set's families of axis m, and record by record
// in axis-m order the axis-m position + 1 of the record each of those
// families pairs it with (0: none), 3 bytes per record and family
// (little-endian), in tiles of 16 families (a 48-byte row per record and
// tile). Filled by gather (GatherOptions::record), read by gather_recorded.
struct PairTable {
    static constexpr int kTile = 16;             // columns per tile
    static constexpr int kEntry = 3;             // bytes per entry
    static constexpr int kRow = kTile * kEntry;  // bytes per record and tile (a multiple of 16)
    static constexpr int64_t kMaxRecords = (int64_t(1) << 24) - 2;  // position + 1 fits 3 bytes
    // entry `lane` of a row (reads 4 bytes: a block has slack after its last row)
    static uint32_t entry(const uint8_t* row, int lane) {
        uint32_t x;
        std::memcpy(&x, row + kEntry * lane, 4);
        return x & 0xFFFFFFu;
    }
    int64_t n = 0;     // records
    int64_t nfam = 0;  // families of the set
    bool with_stand_in = false;
    std::vector<int32_t> slot;      // family -> its column in its axis's table
    std::vector<int32_t> fam_axis;  // family -> main axis
    int64_t cols[3] = {0, 0, 0};    // axis m -> how many of the set's families it has
    std::vector<int32_t> vec;       // every family's vector, 3 per family (checked on use)
    std::vector<float> dir;         // unit direction of every family, 3 per family
    std::vector<double> weight;     // every family's weight
    // axis m: tiles of kTile columns; tile t's row for the record at axis-m
    // position p is snd[m].data()[(t * n + p) * kRow ...]
    ZeroBlock snd[3];
    std::vector<uint8_t> filled;  // family -> recorded yet
    size_t bytes() const { return snd[0].size() + snd[1].size() + snd[2].size(); }

    // Write one tile of axis m from a family-major buffer of kTile columns of
    // n int32 entries (column `lane` for every lane set in `lanes`), and
    // clear the buffer as it is read.
    void write_tile(int m, int64_t tile, uint32_t lanes, int32_t* buf);
};

// An empty table for the pairs of these families over the records of s
// (zero pages: memory is used as the pairs are written).
PairTable make_pair_table(const LineSystem& ls, const Family* fams, int64_t nf, bool with_stand_in);

// The gathering pass over the recorded families `sel` (every one of them
// recorded), from the table instead of the lines: the same pairs, the same
// weights, the sums added per record in family order (results equal
// gather's to float rounding, and do not depend on `threads`).
void gather_recorded(const LineSystem& ls, const PairTable& table, const int64_t* sel, int64_t nsel,
                     const float* val, double* out, double* vis, int threads,
                     const StopCheck& stop);

}  // namespace voxgi
