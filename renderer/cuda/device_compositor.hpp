// The GPU's PartialCompositor (renderer.hpp): a sharded frame's partials, left on their GPUs
// by render_partial_on_device, gathered on one device and composited there (composite.cuh).
//
//   transfer  each partial of another device copied into this device's staging buffers
//             (cudaMemcpyPeerAsync: over NVLink or PCIe where the two devices are peers, the
//             source pool opened to this device once; otherwise the driver stages it through
//             host memory). Partials already on this device are read where they lie.
//   merge     front to back, one thread a pixel, and the background
//   copy_out  the finished image (RGB8 and/or float) to host memory through pinned buffers
//
// Each step is timed with CUDA events on the compositor's own stream.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "catgs/renderer.hpp"

namespace catgs::cuda {

class DeviceCompositor final : public PartialCompositor {
public:
    /// Composites on `device` (made current around each call). Throws catgs::Error when the
    /// device does not exist.
    explicit DeviceCompositor(int device);
    ~DeviceCompositor() override;
    DeviceCompositor(const DeviceCompositor&) = delete;
    DeviceCompositor& operator=(const DeviceCompositor&) = delete;

    CompositeTimes composite(const std::vector<DevicePartialImage>& front_to_back,
                             const std::array<float, 3>& background, ImageF* rgb, ImageRGB8* rgb8) override;
    int device() const override;

private:
    struct Impl;  // device buffers and events: kept out of this header, which host C++ includes
    std::unique_ptr<Impl> impl_;
};

}  // namespace catgs::cuda
