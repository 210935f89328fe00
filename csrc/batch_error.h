// The display's per-pixel error from batch means (docs/design.md §6).
#pragma once

#include <cstdint>

#include "util/parallel.h"

namespace voxgi {

// batches (k, n) float32: k >= 2 batch means of `size` frames each for n
// values (pixels x channels); the running mean holds `frames` frames. Writes
// per value the standard error of the running mean, sqrt(s_b² size/frames)
// with s_b² the variance between batch means, raised where the farthest
// batch lies more than `crit` (externally studentized, against the spread of
// the other k - 1; infinite: no test) from the others to that batch's jump
// max_j |m_j - M| size/frames, and flags such values (1, else 0).
void batch_error(const float* batches, int64_t k, int64_t n, double size, double frames,
                 double crit, double* stderr_out, uint8_t* flagged, int threads,
                 const StopCheck& stop);

}  // namespace voxgi
