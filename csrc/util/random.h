// Counter-based random numbers for the kernels: a stream hashed from a seed
// and the item's index is the same whatever thread draws it.
#pragma once

#include <cstdint>

namespace voxgi {

// SplitMix64's finalizer (Steele, Lea & Flood 2014): a bijective mix of 64 bits.
inline uint64_t splitmix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

// The top 53 bits of x as a double in [0, 1).
inline double to_unit(uint64_t x) { return double(x >> 11) * (1.0 / 9007199254740992.0); }

}  // namespace voxgi
