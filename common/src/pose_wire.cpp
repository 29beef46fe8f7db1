#include "catgs/common/pose_wire.hpp"

namespace catgs::wire {

v1::Pose to_proto(const Pose& pose) {
    v1::Pose p;
    const auto c = camera_centre(pose);
    const auto q = camera_to_world_quaternion(pose);
    p.mutable_position()->set_x(c[0]);
    p.mutable_position()->set_y(c[1]);
    p.mutable_position()->set_z(c[2]);
    p.mutable_orientation()->set_w(q[0]);
    p.mutable_orientation()->set_x(q[1]);
    p.mutable_orientation()->set_y(q[2]);
    p.mutable_orientation()->set_z(q[3]);
    return p;
}

Pose from_proto(const v1::Pose& pose) {
    const auto& p = pose.position();
    const auto& q = pose.orientation();
    return pose_from_quaternion({p.x(), p.y(), p.z()}, {q.w(), q.x(), q.y(), q.z()});
}

}  // namespace catgs::wire
