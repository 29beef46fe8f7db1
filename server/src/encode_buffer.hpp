// Scratch memory for encoders, kept per thread from frame to frame and grown, never shrunk.
// Not a std::vector: growing one zero-fills it, and an encoder's worst-case bound (several times
// the compressed size) would then be written, and made resident, on every thread for nothing.
#pragma once

#include <cstddef>
#include <memory>

namespace catgs::server {

class ScratchBuffer {
public:
    /// At least `bytes` writable bytes; the contents are not kept when it grows.
    unsigned char* reserve(std::size_t bytes) {
        if (bytes > capacity_) {
            data_.reset(new unsigned char[bytes]);  // default-initialised: untouched until written
            capacity_ = bytes;
        }
        return data_.get();
    }
    unsigned char* data() const { return data_.get(); }
    std::size_t capacity() const { return capacity_; }

private:
    std::unique_ptr<unsigned char[]> data_;
    std::size_t capacity_ = 0;
};

}  // namespace catgs::server
