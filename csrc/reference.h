// Reference and adjoint variants of the passes over a line system, for the
// tests: what the fast kernels are checked against. Implemented in
// reference.cpp. No pybind11 here.
#pragma once

#include <cstdint>

#include "gather.h"
#include "shoot.h"

namespace voxgi {

// The gathering by a stable counting sort of every family's records by line
// key, then a walk of each line: the reference the one-pass walk is checked
// against. transpose: the transposed operator, out[partner] += val[x] *
// cos_x * weight for the same pairs (x's weight, the partner receives): with
// val = area / S, the power each record delivers per unit sent
// (docs/design.md §5). vis is unchanged by transpose. (opt.record must be
// null.)
int64_t gather_sorted(const LineSystem& ls, const Family* fams, const int64_t* sel, int64_t nsel,
                      const float* val, double* out, double* vis, bool transpose,
                      const GatherOptions& opt, const StopCheck& stop);

// The shooting with the deposit on the sender side: a ray of e carries
// val[e] * cos_e * weight * send_scale[e] (send_scale = area / S: the ray's
// power) and its receivers share it in proportion to recv_area[r] * cos_r;
// hd then holds power, and the direct light conserves energy exactly, at the
// price of per-record aliasing (which voxel catches a ray is not which
// surface is there). (opt: stand-ins and threads only.)
ShootCount shoot_sender_side(const LineSystem& ls, const int32_t* emit, int64_t ne,
                             const Family* fams, int64_t nf, const float* val,
                             const double* send_scale, const double* recv_area, double* hd,
                             double* unfound, const ShootOptions& opt, const StopCheck& stop);

}  // namespace voxgi
