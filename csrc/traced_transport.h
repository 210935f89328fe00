// The solve's traced passes kept as a sparse matrix (docs/design.md §5): the
// rays of one pass of gather_light (vpl_shade.h, its GatherTransport), the
// record each one read and the factor it read it by, summed per record
// pair, so that a later pass applies the same rays as a product with a
// sparse matrix instead of tracing them and looking the records up again.
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "util/parallel.h"

namespace voxgi {

// In place: the n rays of each of the P rows (row p at p * n, as
// gather_light's GatherTransport wrote them) become that row's distinct
// records (column = to_column[record], the caller's order; to_column null:
// the record itself), in ascending column order, each with the sum of its
// rays' weights; rays that read nothing (record -1) or read with a weight
// of zero are dropped. The rows are then moved to the front: row p holds
// entries [row_ptr[p], row_ptr[p + 1]) of record and weight (3 floats an
// entry). Returns the number of entries, row_ptr[P]. The same for any
// thread count.
int64_t transport_compact(int64_t P, int n, const int32_t* to_column, int32_t* record,
                          float* weight, int64_t* row_ptr, int threads, const StopCheck& stop);

// out[p] = sum over the entries e of row p of weight[e] * val[column[e]],
// per channel (RGB), summed in double in column order; out (P, 3) is
// overwritten; val has N rows. The same for any thread count. Throws
// std::invalid_argument for a column outside [0, N) (checked as the entries
// are read: a pass reads each once).
void transport_apply(int64_t P, int64_t N, const int64_t* row_ptr, const int32_t* column,
                     const float* weight, const double* val, double* out, int threads,
                     const StopCheck& stop);

}  // namespace voxgi
