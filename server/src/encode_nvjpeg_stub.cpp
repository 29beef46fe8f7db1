// nvJPEG when the build has none (CATGS_NVJPEG=OFF, CI's build): every call says so.
#include "catgs/error.hpp"
#include "catgs/server/encode_methods.hpp"

namespace catgs::server {

bool nvjpeg_built() {
    return false;
}

std::string nvjpeg_unusable_reason() {
    return "catgs-server was built without nvJPEG (configure with -DCATGS_NVJPEG=ON)";
}

void encode_jpeg_nvjpeg(const ImageRGB8&, int, bool, std::string&) {
    throw Error("jpeg encoder: " + nvjpeg_unusable_reason());
}

}  // namespace catgs::server
