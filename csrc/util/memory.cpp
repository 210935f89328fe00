#include "util/memory.h"

#include <sys/mman.h>

#include <new>

namespace voxgi {

void ZeroBlock::release() {
    if (p_) munmap(p_, size_ + kSlack);
    p_ = nullptr;
    size_ = 0;
}

void ZeroBlock::allocate(size_t bytes) {
    release();
    // huge pages where the kernel grants them (transparent huge pages in
    // "madvise" mode): fewer TLB misses on a table streamed end to end
    void* q =
        mmap(nullptr, bytes + kSlack, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (q == MAP_FAILED) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
    madvise(q, bytes + kSlack, MADV_HUGEPAGE);
#endif
    p_ = static_cast<uint8_t*>(q);
    size_ = bytes;
}

ZeroBlock& ZeroBlock::operator=(ZeroBlock&& o) noexcept {
    if (this != &o) {
        release();
        p_ = o.p_;
        size_ = o.size_;
        o.p_ = nullptr;
        o.size_ = 0;
    }
    return *this;
}

}  // namespace voxgi
