// Small SSE2 functions for the hot loops (every x86-64 has SSE2; elsewhere the
// scalar forms run). Each makes the same IEEE operations in the same
// order as its scalar form, so results do not depend on which one runs.
#pragma once

#include <cstdint>
#include <cstring>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace voxgi {

inline float dot3(const float* a, const float* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

#if defined(__SSE2__)
// (t0 + t1) + t2: dot3's order of additions, lane 3 ignored
inline float sum3(__m128 t) {
    const __m128 s = _mm_add_ss(t, _mm_shuffle_ps(t, t, _MM_SHUFFLE(1, 1, 1, 1)));
    return _mm_cvtss_f32(_mm_add_ss(s, _mm_shuffle_ps(t, t, _MM_SHUFFLE(2, 2, 2, 2))));
}
#endif

// a[k] += double(x[k]) * c for k < 4 (a 16-byte aligned)
inline void madd4(double* a, const float* x, double c) {
#if defined(__SSE2__)
    const __m128 v = _mm_loadu_ps(x);
    const __m128d cc = _mm_set1_pd(c);
    _mm_store_pd(a, _mm_add_pd(_mm_load_pd(a), _mm_mul_pd(_mm_cvtps_pd(v), cc)));
    _mm_store_pd(a + 2,
                 _mm_add_pd(_mm_load_pd(a + 2), _mm_mul_pd(_mm_cvtps_pd(_mm_movehl_ps(v, v)), cc)));
#else
    for (int k = 0; k < 4; ++k) a[k] += x[k] * c;
#endif
}

// Copy `bytes` (a multiple of 16) from an aligned buffer to aligned memory
// that nothing reads back soon: streamed past the cache, no read for
// ownership. Call store_fence() after the last one.
inline void stream_copy(uint8_t* dst, const uint8_t* src, int bytes) {
#if defined(__SSE2__)
    for (int q = 0; q < bytes; q += 16)
        _mm_stream_si128(reinterpret_cast<__m128i*>(dst + q),
                         _mm_load_si128(reinterpret_cast<const __m128i*>(src + q)));
#else
    std::memcpy(dst, src, bytes);
#endif
}

inline void store_fence() {
#if defined(__SSE2__)
    _mm_sfence();
#endif
}

}  // namespace voxgi
