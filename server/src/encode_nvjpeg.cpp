// nvJPEG (CATGS_NVJPEG): host RGB8 frames encoded on the GPU. Each encoder thread keeps its
// own stream, encoder state and parameters, and pinned upload/download buffers grown to the
// largest frame it has seen: creating them per frame costs more than the encode, and nvJPEG's
// states must not be shared between threads (the library handle may be).
#include <cuda_runtime_api.h>
#include <nvjpeg.h>

#include <cstring>
#include <string>

#include "catgs/error.hpp"
#include "catgs/server/encode_methods.hpp"

namespace catgs::server {
namespace {

std::string nvjpeg_status_name(nvjpegStatus_t status) {
    switch (status) {
        case NVJPEG_STATUS_SUCCESS:
            return "success";
        case NVJPEG_STATUS_NOT_INITIALIZED:
            return "not initialized";
        case NVJPEG_STATUS_INVALID_PARAMETER:
            return "invalid parameter";
        case NVJPEG_STATUS_BAD_JPEG:
            return "bad JPEG";
        case NVJPEG_STATUS_JPEG_NOT_SUPPORTED:
            return "JPEG not supported";
        case NVJPEG_STATUS_ALLOCATOR_FAILURE:
            return "allocator failure";
        case NVJPEG_STATUS_EXECUTION_FAILED:
            return "execution failed";
        case NVJPEG_STATUS_ARCH_MISMATCH:
            return "architecture mismatch";
        case NVJPEG_STATUS_INTERNAL_ERROR:
            return "internal error";
        case NVJPEG_STATUS_IMPLEMENTATION_NOT_SUPPORTED:
            return "implementation not supported";
        default:
            return "status " + std::to_string(static_cast<int>(status));
    }
}

void check(nvjpegStatus_t status, const char* call) {
    if (status != NVJPEG_STATUS_SUCCESS)
        throw Error(std::string("jpeg encoder (nvJPEG): ") + call + ": " + nvjpeg_status_name(status));
}

void check(cudaError_t status, const char* call) {
    if (status != cudaSuccess)
        throw Error(std::string("jpeg encoder (nvJPEG): ") + call + ": " + cudaGetErrorString(status));
}

// The library handle, created once. It is never destroyed: at process exit the CUDA runtime
// may already be gone, and destroying it then fails or crashes.
struct Library {
    nvjpegHandle_t handle = nullptr;
    std::string unusable;  // why it cannot be used, or ""
};

const Library& library() {
    static const Library lib = [] {
        Library l;
        int devices = 0;
        if (const cudaError_t e = cudaGetDeviceCount(&devices); e != cudaSuccess) {
            l.unusable = std::string("no usable CUDA device (") + cudaGetErrorString(e) + ")";
        } else if (devices == 0) {
            l.unusable = "no CUDA device";
        } else if (const nvjpegStatus_t s = nvjpegCreateSimple(&l.handle); s != NVJPEG_STATUS_SUCCESS) {
            l.unusable = "nvjpegCreateSimple failed: " + nvjpeg_status_name(s);
            l.handle = nullptr;
        }
        return l;
    }();
    return lib;
}

// One thread's encoder: freed when the thread ends.
class ThreadEncoder {
public:
    explicit ThreadEncoder(nvjpegHandle_t handle) : handle_(handle) {
        check(cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking), "cudaStreamCreateWithFlags");
        check(nvjpegEncoderStateCreate(handle_, &state_, stream_), "nvjpegEncoderStateCreate");
        check(nvjpegEncoderParamsCreate(handle_, &params_, stream_), "nvjpegEncoderParamsCreate");
    }
    ~ThreadEncoder() {
        // Errors are ignored: at process exit the runtime may be unloading.
        if (params_) nvjpegEncoderParamsDestroy(params_);
        if (state_) nvjpegEncoderStateDestroy(state_);
        if (device_) cudaFree(device_);
        if (upload_) cudaFreeHost(upload_);
        if (download_) cudaFreeHost(download_);
        if (stream_) cudaStreamDestroy(stream_);
    }
    ThreadEncoder(const ThreadEncoder&) = delete;
    ThreadEncoder& operator=(const ThreadEncoder&) = delete;

    void encode(const ImageRGB8& image, int quality, bool chroma_444, std::string& out) {
        const std::size_t bytes = image.rgb.size();
        grow(bytes);
        check(nvjpegEncoderParamsSetQuality(params_, quality, stream_), "nvjpegEncoderParamsSetQuality");
        check(nvjpegEncoderParamsSetSamplingFactors(params_, chroma_444 ? NVJPEG_CSS_444 : NVJPEG_CSS_420, stream_),
              "nvjpegEncoderParamsSetSamplingFactors");
        // Standard tables, like TurboJPEG's: an optimising pass would cost a second scan.
        check(nvjpegEncoderParamsSetOptimizedHuffman(params_, 0, stream_), "nvjpegEncoderParamsSetOptimizedHuffman");
        std::memcpy(upload_, image.rgb.data(), bytes);
        check(cudaMemcpyAsync(device_, upload_, bytes, cudaMemcpyHostToDevice, stream_), "cudaMemcpyAsync");
        nvjpegImage_t source{};
        source.channel[0] = static_cast<unsigned char*>(device_);
        source.pitch[0] = 3 * static_cast<std::size_t>(image.width);
        check(
            nvjpegEncodeImage(handle_, state_, params_, &source, NVJPEG_INPUT_RGBI, image.width, image.height, stream_),
            "nvjpegEncodeImage");
        std::size_t length = 0;
        check(nvjpegEncodeRetrieveBitstream(handle_, state_, nullptr, &length, stream_),
              "nvjpegEncodeRetrieveBitstream (length)");
        check(cudaStreamSynchronize(stream_), "cudaStreamSynchronize");
        grow_download(length);
        check(nvjpegEncodeRetrieveBitstream(handle_, state_, download_, &length, stream_),
              "nvjpegEncodeRetrieveBitstream");
        check(cudaStreamSynchronize(stream_), "cudaStreamSynchronize");
        out.assign(reinterpret_cast<const char*>(download_), length);
    }

private:
    void grow(std::size_t bytes) {
        if (bytes <= capacity_) return;
        if (device_) cudaFree(device_);
        if (upload_) cudaFreeHost(upload_);
        device_ = upload_ = nullptr;
        capacity_ = 0;
        check(cudaMalloc(&device_, bytes), "cudaMalloc");
        check(cudaMallocHost(&upload_, bytes), "cudaMallocHost");
        capacity_ = bytes;
    }
    void grow_download(std::size_t bytes) {
        if (bytes <= download_capacity_) return;
        if (download_) cudaFreeHost(download_);
        download_ = nullptr;
        download_capacity_ = 0;
        check(cudaMallocHost(reinterpret_cast<void**>(&download_), bytes), "cudaMallocHost");
        download_capacity_ = bytes;
    }

    nvjpegHandle_t handle_;
    cudaStream_t stream_ = nullptr;
    nvjpegEncoderState_t state_ = nullptr;
    nvjpegEncoderParams_t params_ = nullptr;
    void* device_ = nullptr;
    void* upload_ = nullptr;
    std::size_t capacity_ = 0;
    unsigned char* download_ = nullptr;
    std::size_t download_capacity_ = 0;
};

}  // namespace

bool nvjpeg_built() {
    return true;
}

std::string nvjpeg_unusable_reason() {
    return library().unusable;
}

void encode_jpeg_nvjpeg(const ImageRGB8& image, int quality, bool chroma_444, std::string& out) {
    const Library& lib = library();
    if (!lib.handle) throw Error("jpeg encoder (nvJPEG): " + lib.unusable);
    thread_local ThreadEncoder encoder(lib.handle);
    encoder.encode(image, quality, chroma_444, out);
}

}  // namespace catgs::server
