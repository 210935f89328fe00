// Large zero-initialised blocks taken straight from the operating system.
#pragma once

#include <cstddef>
#include <cstdint>

namespace voxgi {

// Anonymous memory: its pages are zero and cost nothing until written, so a
// table that is filled a part at a time only uses what has been filled.
// kSlack readable bytes follow the last one (for 4-byte loads of 3-byte
// entries).
class ZeroBlock {
   public:
    static constexpr size_t kSlack = 16;
    ZeroBlock() = default;
    ZeroBlock(const ZeroBlock&) = delete;
    ZeroBlock& operator=(const ZeroBlock&) = delete;
    ZeroBlock(ZeroBlock&& o) noexcept : p_(o.p_), size_(o.size_) {
        o.p_ = nullptr;
        o.size_ = 0;
    }
    ZeroBlock& operator=(ZeroBlock&& o) noexcept;
    ~ZeroBlock() { release(); }

    void allocate(size_t bytes);  // throws std::bad_alloc
    void release();
    uint8_t* data() const { return p_; }
    size_t size() const { return size_; }

   private:
    uint8_t* p_ = nullptr;
    size_t size_ = 0;
};

}  // namespace voxgi
