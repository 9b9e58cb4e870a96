// Fixed-size Eigen aliases: every size is known at compile time, so nothing allocates.
#pragma once

#include <cstdint>
#include "graspguide/eigen.h"

#include "graspguide/config.h"
#include "graspguide_cue/pwm.h"  // Pwm

namespace graspguide {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Vec6 = Eigen::Matrix<T, 6, 1>;
template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Quat = Eigen::Quaternion<T>;

// One column per contact, in the hand frame.
template <typename T, int K>
using Contacts = Eigen::Matrix<T, 3, K>;
// Grasp matrix G (6 x 3k) and its transpose.
template <typename T, int K>
using GraspMat = Eigen::Matrix<T, 6, 3 * K>;
template <typename T, int K>
using GraspMatT = Eigen::Matrix<T, 3 * K, 6>;
// Contact forces, [x y z] of each contact in its own frame.
template <typename T, int K>
using ForceVec = Eigen::Matrix<T, 3 * K, 1>;
// Orthonormal basis of null(G): 3k x (3k - 6).
template <typename T, int K>
using NullBasis = Eigen::Matrix<T, 3 * K, 3 * K - 6>;
template <typename T, int K>
using NullVec = Eigen::Matrix<T, 3 * K - 6, 1>;
template <typename T, int K>
using LevelVec = Eigen::Matrix<T, K, 1>;

}  // namespace graspguide
