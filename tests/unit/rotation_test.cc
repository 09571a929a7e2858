#include "motionpipe/math/rotation.h"

#include <gtest/gtest.h>

#include <random>

namespace motionpipe {
namespace {

Mat3 RandomRotation(std::mt19937& rng) {
  std::normal_distribution<double> normal;
  return QuatToMatrix(Normalized({normal(rng), normal(rng), normal(rng), normal(rng)}));
}

TEST(Rotation, AxisAngleMatrixRoundTrip) {
  std::mt19937 rng(1);
  for (int k = 0; k < 1000; ++k) {
    const Mat3 r = RandomRotation(rng);
    EXPECT_LT(MaxAbsDiff(AxisAngleToMatrix(MatrixToAxisAngle(r)), r), 1e-12);
  }
}

TEST(Rotation, AxisAngleNearZeroAndPi) {
  for (double angle : {0.0, 1e-12, 1e-7, 1e-3, kPi - 1e-9, kPi}) {
    const Vec3 aa{angle / std::sqrt(3.0), angle / std::sqrt(3.0), -angle / std::sqrt(3.0)};
    const Mat3 r = AxisAngleToMatrix(aa);
    EXPECT_LT(MaxAbsDiff(AxisAngleToMatrix(MatrixToAxisAngle(r)), r), 1e-9) << angle;
    EXPECT_NEAR(Norm(MatrixToAxisAngle(r)), angle, 1e-6) << angle;
  }
}

TEST(Rotation, KnownAxisAngle) {
  // 90 degrees about z maps x to y.
  const Vec3 y = AxisAngleToMatrix({0, 0, kPi / 2}) * Vec3{1, 0, 0};
  EXPECT_NEAR(y.x, 0, 1e-12);
  EXPECT_NEAR(y.y, 1, 1e-12);
  EXPECT_LT(MaxAbsDiff(AxisAngleToMatrix({kPi / 3, 0, 0}), RotX(kPi / 3)), 1e-12);
}

TEST(Rotation, QuaternionMatchesMatrix) {
  std::mt19937 rng(2);
  for (int k = 0; k < 200; ++k) {
    const Mat3 a = RandomRotation(rng), b = RandomRotation(rng);
    const Quat qa = MatrixToQuat(a), qb = MatrixToQuat(b);
    EXPECT_LT(MaxAbsDiff(QuatToMatrix(qa * qb), a * b), 1e-12);
    EXPECT_LT(MaxAbsDiff(QuatToMatrix(AxisAngleToQuat(MatrixToAxisAngle(a))), a), 1e-12);
  }
}

TEST(Rotation, SixDIsFirstTwoRowsAndGramSchmidtInverts) {
  std::mt19937 rng(3);
  const Mat3 r = RandomRotation(rng);
  const Rot6d six = MatrixToRot6d(r);
  EXPECT_EQ(six[0], r[0][0]);
  EXPECT_EQ(six[2], r[0][2]);
  EXPECT_EQ(six[3], r[1][0]);
  EXPECT_EQ(six[5], r[1][2]);
  EXPECT_LT(MaxAbsDiff(Rot6dToMatrix(six), r), 1e-12);
  // Gram-Schmidt: a scaled, skewed pair still gives the rotation whose first row is the first
  // vector.
  Rot6d noisy = six;
  for (int k = 0; k < 3; ++k) noisy[static_cast<size_t>(k)] *= 3.0;
  for (int k = 3; k < 6; ++k)
    noisy[static_cast<size_t>(k)] += 0.2 * six[static_cast<size_t>(k - 3)];
  EXPECT_LT(MaxAbsDiff(Rot6dToMatrix(noisy), r), 1e-12);
  const Mat3 m = Rot6dToMatrix({0.3, -2, 0.1, 5, 1, 1});
  EXPECT_LT(MaxAbsDiff(m * Transpose(m), Mat3::Identity()), 1e-12);
}

TEST(Rotation, EulerRoundTripAllOrders) {
  std::mt19937 rng(4);
  for (const char* order : {"XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"}) {
    for (int k = 0; k < 200; ++k) {
      const Mat3 r = RandomRotation(rng);
      EXPECT_LT(MaxAbsDiff(EulerToMatrix(order, MatrixToEuler(order, r)), r), 1e-9) << order;
    }
    // Gimbal lock: middle angle +-90 degrees.
    for (double middle : {kPi / 2, -kPi / 2}) {
      const Mat3 r = EulerToMatrix(order, {0.7, middle, -0.4});
      EXPECT_LT(MaxAbsDiff(EulerToMatrix(order, MatrixToEuler(order, r)), r), 1e-9)
          << order << " " << middle;
    }
  }
  EXPECT_FALSE(EulerOrderValid("XXY"));
  EXPECT_FALSE(EulerOrderValid("XY"));
}

TEST(Rotation, HeadingIsZyxYawAndRemovable) {
  const Mat3 r = RotZ(1.1) * RotY(0.3) * RotX(-0.6);
  EXPECT_NEAR(HeadingZYX(r), 1.1, 1e-12);
  EXPECT_NEAR(HeadingZYX(RemoveHeading(r)), 0.0, 1e-12);
  EXPECT_LT(MaxAbsDiff(RemoveHeading(r), RotY(0.3) * RotX(-0.6)), 1e-12);
}

TEST(Rotation, RotationBetweenAndTwoDirections) {
  const Vec3 a{1, 2, 3}, b{-2, 0.5, 1};
  const Vec3 mapped = RotationBetween(a, b) * a;
  EXPECT_NEAR(Norm(Cross(mapped, b)), 0, 1e-12);
  EXPECT_GT(Dot(mapped, b), 0);
  const Vec3 opposite = RotationBetween({0, 1, 0}, {0, -1, 0}) * Vec3{0, 1, 0};
  EXPECT_NEAR(opposite.y, -1, 1e-12);
  const Mat3 r = RotationFromTwoDirections({0, 1, 0}, {1, 0, 0}, {0, 0, 1}, {0, 1, 0});
  EXPECT_NEAR((r * Vec3{0, 1, 0}).z, 1, 1e-12);
  EXPECT_NEAR((r * Vec3{1, 0, 0}).y, 1, 1e-12);
}

TEST(Rotation, SlerpEndpointsAndMidpoint) {
  const Quat a = AxisAngleToQuat({0, 0, 0}), b = AxisAngleToQuat({0, 0, 1.0});
  EXPECT_NEAR(Norm(QuatToAxisAngle(Slerp(a, b, 0.5))), 0.5, 1e-12);
  EXPECT_LT(MaxAbsDiff(QuatToMatrix(Slerp(a, b, 1)), QuatToMatrix(b)), 1e-12);
}

}  // namespace
}  // namespace motionpipe
