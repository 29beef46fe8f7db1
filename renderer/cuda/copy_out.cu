#include "copy_out.cuh"

#include <cuda.h>  // the driver's types for cuStreamWaitValue32; resolved at run time, not linked

#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

/// Rows [row_begin, row_end) of an image of `width` pixels, `channels` values of V a pixel.
template <typename V>
void copy_rows(PinnedArray<V>* host, const V* device, int width, int channels, int row_begin, int row_end,
               cudaStream_t s) {
    if (!device || row_end <= row_begin) return;
    const std::size_t row = static_cast<std::size_t>(width) * channels;
    const std::size_t first = row * static_cast<std::size_t>(row_begin);
    CATGS_CUDA_CHECK(cudaMemcpyAsync(host->data() + first, device + first,
                                     row * static_cast<std::size_t>(row_end - row_begin) * sizeof(V),
                                     cudaMemcpyDeviceToHost, s));
}

using StreamWaitValue32 = CUresult (*)(CUstream, CUdeviceptr, cuuint32_t, unsigned int);

/// The driver's cuStreamWaitValue32, looked up once; null where it is missing. Through the
/// runtime's entry-point query, so that binaries without a driver (CI) still load.
StreamWaitValue32 stream_wait_value() {
    static const StreamWaitValue32 fn = [] {
        void* address = nullptr;
        cudaDriverEntryPointQueryResult found = cudaDriverEntryPointSymbolNotFound;
        constexpr unsigned kDriverApiVersion = 12000;  // the _v2 memory operations
        if (cudaGetDriverEntryPointByVersion("cuStreamWaitValue32", &address, kDriverApiVersion, cudaEnableDefault,
                                             &found) != cudaSuccess ||
            found != cudaDriverEntryPointSuccess) {
            cudaGetLastError();  // clear it: the fallback is not an error
            return StreamWaitValue32{nullptr};
        }
        return reinterpret_cast<StreamWaitValue32>(address);
    }();
    return fn;
}

}  // namespace

void reserve_copy_out(const CopyOutArgs& a, std::size_t pixels) {
    if (a.rgb8) a.host_rgb8->reserve(3 * pixels);
    if (a.rgb_float) a.host_float->reserve(3 * pixels);
    if (a.transmittance) a.host_transmittance->reserve(pixels);
    if (a.stopped) a.host_stopped->reserve(pixels);
}

void copy_out(const CopyOutArgs& a, int row_begin, int row_end, cudaStream_t s) {
    copy_rows(a.host_rgb8, a.rgb8, a.width, 3, row_begin, row_end, s);
    copy_rows(a.host_float, a.rgb_float, a.width, 3, row_begin, row_end, s);
    copy_rows(a.host_transmittance, a.transmittance, a.width, 1, row_begin, row_end, s);
    copy_rows(a.host_stopped, a.stopped, a.width, 1, row_begin, row_end, s);
}

bool wait_for_count(cudaStream_t stream, const unsigned int* counter, unsigned int count) {
    const StreamWaitValue32 wait = stream_wait_value();
    if (!wait) return false;
    // GEQ is cyclic ((int32)(*counter - count) >= 0); counts start at 0 and stay far below 2^31.
    return wait(reinterpret_cast<CUstream>(stream), reinterpret_cast<CUdeviceptr>(counter), count,
                CU_STREAM_WAIT_VALUE_GEQ) == CUDA_SUCCESS;
}

bool stream_memory_waits_available() {
    static const bool available = [] {
        unsigned int* word = nullptr;
        cudaStream_t probe = nullptr;
        if (cudaMalloc(&word, sizeof(unsigned int)) != cudaSuccess ||
            cudaStreamCreateWithFlags(&probe, cudaStreamNonBlocking) != cudaSuccess) {
            cudaGetLastError();
            cudaFree(word);
            return false;
        }
        // A wait already satisfied (0 >= 0): only whether the driver takes it is asked.
        const bool taken = cudaMemsetAsync(word, 0, sizeof(unsigned int), probe) == cudaSuccess &&
                           wait_for_count(probe, word, 0) && cudaStreamSynchronize(probe) == cudaSuccess;
        cudaGetLastError();
        cudaStreamDestroy(probe);
        cudaFree(word);
        return taken;
    }();
    return available;
}

CopyStreams::CopyStreams() {
    for (cudaStream_t& s : band) CATGS_CUDA_CHECK(cudaStreamCreateWithFlags(&s, cudaStreamNonBlocking));
    for (cudaEvent_t* e : {&ready, &drawn}) CATGS_CUDA_CHECK(cudaEventCreateWithFlags(e, cudaEventDisableTiming));
    for (cudaEvent_t& e : copied) CATGS_CUDA_CHECK(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
    CATGS_CUDA_CHECK(cudaMalloc(&tiles_drawn, kMaxCopyBands * sizeof(unsigned int)));
}

CopyStreams::~CopyStreams() {
    // Not checked: runs in destructors.
    for (cudaStream_t s : band)
        if (s) cudaStreamSynchronize(s);
    for (cudaEvent_t e : {ready, drawn})
        if (e) cudaEventDestroy(e);
    for (cudaEvent_t e : copied)
        if (e) cudaEventDestroy(e);
    cudaFree(tiles_drawn);
    for (cudaStream_t s : band)
        if (s) cudaStreamDestroy(s);
}

}  // namespace catgs::cuda
