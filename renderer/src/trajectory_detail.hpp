// Internals shared by the trajectory file formats (trajectory.cpp) and the procedural
// flights (trajectory_flights.cpp): both check that a rotation is one.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include "catgs/host_vector.hpp"

namespace catgs::detail {

using V3 = HostVec3;
using M3 = std::array<double, 9>;  // row-major

// Largest deviation of M^T M from the identity.
inline double orthonormality_error(const M3& m) {
    double worst = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            const double d = m[i] * m[j] + m[3 + i] * m[3 + j] + m[6 + i] * m[6 + j];
            worst = std::max(worst, std::abs(d - (i == j ? 1.0 : 0.0)));
        }
    return worst;
}

}  // namespace catgs::detail
