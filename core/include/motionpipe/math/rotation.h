// Rotation maths on plain double-precision values: axis-angle <-> matrix <-> 6D <-> quaternion,
// Euler angles for BVH, heading (yaw) extraction. Matrices act on column vectors (v' = R v) and are
// stored row-major. REFERENCE.md section 1: the 6D representation is the first two ROWS of R.
#pragma once

#include <array>
#include <cmath>
#include <string>

namespace motionpipe {

struct Vec3 {
  double x = 0, y = 0, z = 0;
  double operator[](int axis) const { return axis == 0 ? x : (axis == 1 ? y : z); }
  double& operator[](int axis) { return axis == 0 ? x : (axis == 1 ? y : z); }
};

inline Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator*(double s, const Vec3& a) { return {s * a.x, s * a.y, s * a.z}; }
inline double Dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double Norm(const Vec3& a) { return std::sqrt(Dot(a, a)); }

struct Mat3 {
  std::array<std::array<double, 3>, 3> m{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  static Mat3 Identity() { return {}; }
  std::array<double, 3>& operator[](int row) { return m[row]; }
  const std::array<double, 3>& operator[](int row) const { return m[row]; }
};

Mat3 operator*(const Mat3& a, const Mat3& b);
Vec3 operator*(const Mat3& r, const Vec3& v);
Mat3 Transpose(const Mat3& r);
// Largest absolute entry difference; for tests and tolerances.
double MaxAbsDiff(const Mat3& a, const Mat3& b);

// Unit quaternion, w first (Hamilton convention).
struct Quat {
  double w = 1, x = 0, y = 0, z = 0;
};
Quat operator*(const Quat& a, const Quat& b);
Quat Normalized(const Quat& q);
// Spherical interpolation along the shorter arc; t in [0, 1].
Quat Slerp(const Quat& a, Quat b, double t);

using Rot6d = std::array<double, 6>;

// Rodrigues' formula; stable for tiny angles.
Mat3 AxisAngleToMatrix(const Vec3& axis_angle);
// Inverse of AxisAngleToMatrix with angle in [0, pi]; stable near 0 and near pi.
Vec3 MatrixToAxisAngle(const Mat3& r);
Quat AxisAngleToQuat(const Vec3& axis_angle);
Vec3 QuatToAxisAngle(const Quat& q);
Mat3 QuatToMatrix(const Quat& q);
Quat MatrixToQuat(const Mat3& r);

// First two rows of r: [r00, r01, r02, r10, r11, r12].
Rot6d MatrixToRot6d(const Mat3& r);
// Gram-Schmidt on the two rows; the third row is their cross product.
Mat3 Rot6dToMatrix(const Rot6d& six);
// The same on float storage (feature rows): writes/reads 6 consecutive floats.
void WriteRot6d(const Mat3& r, float* out);
Mat3 ReadRot6d(const float* in);

Mat3 RotX(double angle);
Mat3 RotY(double angle);
Mat3 RotZ(double angle);

// Heading = the z angle of the ZYX Euler decomposition R = Rz(yaw) Ry(pitch) Rx(roll),
// i.e. atan2(r10, r00) (REFERENCE.md section 2).
double HeadingZYX(const Mat3& r);
// Rz(-heading) R: the same rotation with its heading removed.
Mat3 RemoveHeading(const Mat3& r);

// Euler angles for BVH: `order` is three distinct axis letters ("ZYX", "ZXY", ...), and the matrix
// is R = R_order[0](a0) R_order[1](a1) R_order[2](a2) (intrinsic rotations applied in listed
// order). Angles in radians. Returns false from EulerOrderValid for anything else.
bool EulerOrderValid(const std::string& order);
Mat3 EulerToMatrix(const std::string& order, const std::array<double, 3>& angles);
std::array<double, 3> MatrixToEuler(const std::string& order, const Mat3& r);

// Rotation taking unit direction `from` to unit direction `to` along the shortest arc.
Mat3 RotationBetween(const Vec3& from, const Vec3& to);
// Rotation R with R*from_primary = to_primary and R*from_secondary in the plane of
// (to_primary, to_secondary); both pairs need not be orthogonal or unit length.
Mat3 RotationFromTwoDirections(const Vec3& from_primary, const Vec3& from_secondary,
                               const Vec3& to_primary, const Vec3& to_secondary);

constexpr double kPi = 3.14159265358979323846;

}  // namespace motionpipe
