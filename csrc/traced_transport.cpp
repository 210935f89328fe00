// The traced passes' sparse matrix (see traced_transport.h).
#include "traced_transport.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace voxgi {

namespace {
constexpr int64_t kRows = 1024;  // rows per task
}  // namespace

int64_t transport_compact(int64_t P, int n, const int32_t* to_column, int32_t* record,
                          float* weight, int64_t* row_ptr, int threads, const StopCheck& stop) {
    std::vector<int64_t> len(P, 0);
    for_each_chunked(P, kRows, threads, stop, [&](int64_t p) {
        // a row's rays are few (n <= 4096): sorted by column in a small buffer
        thread_local std::vector<int32_t> idx;
        thread_local std::vector<float> w;
        thread_local std::vector<int32_t> col;
        int32_t* rc = record + p * n;
        float* wt = weight + 3 * p * n;
        idx.resize(n);
        w.assign(wt, wt + 3 * int64_t(n));
        int m = 0;
        for (int k = 0; k < n; ++k) {
            if (rc[k] < 0) continue;
            if (w[3 * k] == 0.f && w[3 * k + 1] == 0.f && w[3 * k + 2] == 0.f) continue;
            rc[k] = to_column ? to_column[rc[k]] : rc[k];
            idx[m++] = k;
        }
        // by column, ties in ray order: the sums below do not depend on the sort
        std::stable_sort(idx.begin(), idx.begin() + m,
                         [&](int32_t a, int32_t b) { return rc[a] < rc[b]; });
        col.resize(m);
        for (int q = 0; q < m; ++q) col[q] = rc[idx[q]];
        int out = 0;
        for (int q = 0; q < m;) {
            const int32_t c = col[q];
            double s[3] = {0.0, 0.0, 0.0};
            for (; q < m && col[q] == c; ++q)
                for (int ch = 0; ch < 3; ++ch) s[ch] += w[3 * idx[q] + ch];
            rc[out] = c;
            for (int ch = 0; ch < 3; ++ch) wt[3 * out + ch] = float(s[ch]);
            ++out;
        }
        len[p] = out;
    });
    // Rows to the front, in order: row p's entries move down to row_ptr[p] <= p * n.
    row_ptr[0] = 0;
    for (int64_t p = 0; p < P; ++p) {
        const int64_t to = row_ptr[p], from = p * n;
        if (to != from) {
            std::copy(record + from, record + from + len[p], record + to);
            std::copy(weight + 3 * from, weight + 3 * (from + len[p]), weight + 3 * to);
        }
        row_ptr[p + 1] = to + len[p];
    }
    return row_ptr[P];
}

void transport_apply(int64_t P, int64_t N, const int64_t* row_ptr, const int32_t* column,
                     const float* weight, const double* val, double* out, int threads,
                     const StopCheck& stop) {
    for_each_chunked(P, kRows, threads, stop, [&](int64_t p) {
        double s0 = 0.0, s1 = 0.0, s2 = 0.0;
        for (int64_t e = row_ptr[p]; e < row_ptr[p + 1]; ++e) {
            if (column[e] < 0 || column[e] >= N)
                throw std::invalid_argument("column: index out of range");
            const double* v = val + 3 * int64_t(column[e]);
            const float* w = weight + 3 * e;
            s0 += double(w[0]) * v[0];
            s1 += double(w[1]) * v[1];
            s2 += double(w[2]) * v[2];
        }
        out[3 * p] = s0, out[3 * p + 1] = s1, out[3 * p + 2] = s2;
    });
}

}  // namespace voxgi
