// A camera pose on the wire (catgs.v1.Pose: the camera centre and the camera-to-world
// quaternion) and back. catgs-client sends poses, catgs-server renders from them: both use
// these two functions, so that neither can read the quaternion the other way round.
#pragma once

#include "catgs/camera.hpp"
#include "catgs/v1/catgs.pb.h"

namespace catgs::wire {

v1::Pose to_proto(const Pose& pose);

/// The quaternion is normalised; throws catgs::Error if its norm is zero or non-finite (the
/// server's request validation refuses those first).
Pose from_proto(const v1::Pose& pose);

}  // namespace catgs::wire
