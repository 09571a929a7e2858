#include "motionpipe/math/rotation.h"

#include <algorithm>

namespace motionpipe {

Mat3 operator*(const Mat3& a, const Mat3& b) {
  Mat3 out;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) {
      out.m[row][col] =
          a.m[row][0] * b.m[0][col] + a.m[row][1] * b.m[1][col] + a.m[row][2] * b.m[2][col];
    }
  }
  return out;
}

Vec3 operator*(const Mat3& r, const Vec3& v) {
  return {r.m[0][0] * v.x + r.m[0][1] * v.y + r.m[0][2] * v.z,
          r.m[1][0] * v.x + r.m[1][1] * v.y + r.m[1][2] * v.z,
          r.m[2][0] * v.x + r.m[2][1] * v.y + r.m[2][2] * v.z};
}

Mat3 Transpose(const Mat3& r) {
  Mat3 out;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) out.m[row][col] = r.m[col][row];
  }
  return out;
}

double MaxAbsDiff(const Mat3& a, const Mat3& b) {
  double worst = 0;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col)
      worst = std::max(worst, std::abs(a.m[row][col] - b.m[row][col]));
  }
  return worst;
}

Quat operator*(const Quat& a, const Quat& b) {
  return {
      a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
      a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

Quat Normalized(const Quat& q) {
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  if (n == 0) return {};
  return {q.w / n, q.x / n, q.y / n, q.z / n};
}

Quat Slerp(const Quat& a, Quat b, double t) {
  double cos_half = a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
  if (cos_half < 0) {
    b = {-b.w, -b.x, -b.y, -b.z};
    cos_half = -cos_half;
  }
  double wa = 1 - t, wb = t;
  if (cos_half < 0.9999) {
    const double half = std::acos(cos_half);
    const double sin_half = std::sin(half);
    wa = std::sin((1 - t) * half) / sin_half;
    wb = std::sin(t * half) / sin_half;
  }
  return Normalized(
      {wa * a.w + wb * b.w, wa * a.x + wb * b.x, wa * a.y + wb * b.y, wa * a.z + wb * b.z});
}

Mat3 AxisAngleToMatrix(const Vec3& aa) {
  const double theta2 = Dot(aa, aa);
  const double theta = std::sqrt(theta2);
  // sin(t)/t and (1-cos t)/t^2 by their Taylor series near zero.
  double a, b;
  if (theta < 1e-4) {
    a = 1 - theta2 / 6;
    b = 0.5 - theta2 / 24;
  } else {
    a = std::sin(theta) / theta;
    b = (1 - std::cos(theta)) / theta2;
  }
  const double x = aa.x, y = aa.y, z = aa.z;
  Mat3 r;
  r.m[0] = {1 - b * (y * y + z * z), -a * z + b * x * y, a * y + b * x * z};
  r.m[1] = {a * z + b * x * y, 1 - b * (x * x + z * z), -a * x + b * y * z};
  r.m[2] = {-a * y + b * x * z, a * x + b * y * z, 1 - b * (x * x + y * y)};
  return r;
}

Quat MatrixToQuat(const Mat3& r) {
  // Shepperd's method: pick the largest diagonal term for stability.
  const double trace = r.m[0][0] + r.m[1][1] + r.m[2][2];
  Quat q;
  if (trace > 0) {
    const double s = std::sqrt(trace + 1.0) * 2;
    q = {0.25 * s, (r.m[2][1] - r.m[1][2]) / s, (r.m[0][2] - r.m[2][0]) / s,
         (r.m[1][0] - r.m[0][1]) / s};
  } else if (r.m[0][0] > r.m[1][1] && r.m[0][0] > r.m[2][2]) {
    const double s = std::sqrt(1.0 + r.m[0][0] - r.m[1][1] - r.m[2][2]) * 2;
    q = {(r.m[2][1] - r.m[1][2]) / s, 0.25 * s, (r.m[0][1] + r.m[1][0]) / s,
         (r.m[0][2] + r.m[2][0]) / s};
  } else if (r.m[1][1] > r.m[2][2]) {
    const double s = std::sqrt(1.0 + r.m[1][1] - r.m[0][0] - r.m[2][2]) * 2;
    q = {(r.m[0][2] - r.m[2][0]) / s, (r.m[0][1] + r.m[1][0]) / s, 0.25 * s,
         (r.m[1][2] + r.m[2][1]) / s};
  } else {
    const double s = std::sqrt(1.0 + r.m[2][2] - r.m[0][0] - r.m[1][1]) * 2;
    q = {(r.m[1][0] - r.m[0][1]) / s, (r.m[0][2] + r.m[2][0]) / s, (r.m[1][2] + r.m[2][1]) / s,
         0.25 * s};
  }
  if (q.w < 0) q = {-q.w, -q.x, -q.y, -q.z};
  return Normalized(q);
}

Mat3 QuatToMatrix(const Quat& in) {
  const Quat q = Normalized(in);
  const double w = q.w, x = q.x, y = q.y, z = q.z;
  Mat3 r;
  r.m[0] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)};
  r.m[1] = {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)};
  r.m[2] = {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)};
  return r;
}

Quat AxisAngleToQuat(const Vec3& aa) {
  const double theta = Norm(aa);
  const double half = 0.5 * theta;
  // sin(half)/theta -> 1/2 as theta -> 0.
  const double k = theta < 1e-8 ? 0.5 - theta * theta / 48 : std::sin(half) / theta;
  return {std::cos(half), k * aa.x, k * aa.y, k * aa.z};
}

Vec3 QuatToAxisAngle(const Quat& in) {
  Quat q = Normalized(in);
  if (q.w < 0) q = {-q.w, -q.x, -q.y, -q.z};
  const double sin_half = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
  const double theta = 2 * std::atan2(sin_half, q.w);
  // theta / sin(theta/2) -> 2 as theta -> 0.
  const double k = sin_half < 1e-8 ? 2.0 / q.w : theta / sin_half;
  return {k * q.x, k * q.y, k * q.z};
}

Vec3 MatrixToAxisAngle(const Mat3& r) { return QuatToAxisAngle(MatrixToQuat(r)); }

Rot6d MatrixToRot6d(const Mat3& r) {
  return {r.m[0][0], r.m[0][1], r.m[0][2], r.m[1][0], r.m[1][1], r.m[1][2]};
}

Mat3 Rot6dToMatrix(const Rot6d& six) {
  Vec3 a{six[0], six[1], six[2]};
  Vec3 b{six[3], six[4], six[5]};
  const double na = Norm(a);
  const Vec3 r0 = na > 0 ? (1.0 / na) * a : Vec3{1, 0, 0};
  Vec3 b_orth = b - Dot(r0, b) * r0;
  const double nb = Norm(b_orth);
  Vec3 r1;
  if (nb > 1e-12) {
    r1 = (1.0 / nb) * b_orth;
  } else {  // degenerate input: pick any unit vector orthogonal to r0
    const Vec3 helper = std::abs(r0.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
    const Vec3 c = Cross(r0, helper);
    r1 = (1.0 / Norm(c)) * c;
  }
  const Vec3 r2 = Cross(r0, r1);
  Mat3 out;
  out.m[0] = {r0.x, r0.y, r0.z};
  out.m[1] = {r1.x, r1.y, r1.z};
  out.m[2] = {r2.x, r2.y, r2.z};
  return out;
}

void WriteRot6d(const Mat3& r, float* out) {
  const Rot6d six = MatrixToRot6d(r);
  for (size_t k = 0; k < 6; ++k) out[k] = static_cast<float>(six[k]);
}

Mat3 ReadRot6d(const float* in) {
  return Rot6dToMatrix({in[0], in[1], in[2], in[3], in[4], in[5]});
}

Mat3 RotX(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Mat3 r;
  r.m = {{{1, 0, 0}, {0, c, -s}, {0, s, c}}};
  return r;
}
Mat3 RotY(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Mat3 r;
  r.m = {{{c, 0, s}, {0, 1, 0}, {-s, 0, c}}};
  return r;
}
Mat3 RotZ(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Mat3 r;
  r.m = {{{c, -s, 0}, {s, c, 0}, {0, 0, 1}}};
  return r;
}

double HeadingZYX(const Mat3& r) { return std::atan2(r.m[1][0], r.m[0][0]); }

Mat3 RemoveHeading(const Mat3& r) { return RotZ(-HeadingZYX(r)) * r; }

namespace {
int AxisIndex(char letter) {
  switch (letter) {
    case 'X':
    case 'x':
      return 0;
    case 'Y':
    case 'y':
      return 1;
    case 'Z':
    case 'z':
      return 2;
    default:
      return -1;
  }
}
Mat3 AxisRotation(int axis, double angle) {
  return axis == 0 ? RotX(angle) : (axis == 1 ? RotY(angle) : RotZ(angle));
}
}  // namespace

bool EulerOrderValid(const std::string& order) {
  if (order.size() != 3) return false;
  const int i = AxisIndex(order[0]), j = AxisIndex(order[1]), k = AxisIndex(order[2]);
  return i >= 0 && j >= 0 && k >= 0 && i != j && j != k && i != k;
}

Mat3 EulerToMatrix(const std::string& order, const std::array<double, 3>& angles) {
  return AxisRotation(AxisIndex(order[0]), angles[0]) *
         AxisRotation(AxisIndex(order[1]), angles[1]) *
         AxisRotation(AxisIndex(order[2]), angles[2]);
}

std::array<double, 3> MatrixToEuler(const std::string& order, const Mat3& r) {
  const int i = AxisIndex(order[0]), j = AxisIndex(order[1]), k = AxisIndex(order[2]);
  // Even permutations of XYZ (XYZ, YZX, ZXY) have sign +1, odd ones -1.
  const double s = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;
  const double sin_b = std::clamp(s * r.m[i][k], -1.0, 1.0);
  const double b = std::asin(sin_b);
  double a, c;
  if (std::abs(sin_b) < 1.0 - 1e-12) {
    a = std::atan2(-s * r.m[j][k], r.m[k][k]);
    c = std::atan2(-s * r.m[i][j], r.m[i][i]);
  } else {  // gimbal lock: only a +- c is defined; put it all in a
    c = 0;
    a = std::atan2(s * r.m[k][j], r.m[j][j]);
  }
  return {a, b, c};
}

Mat3 RotationBetween(const Vec3& from, const Vec3& to) {
  const Vec3 f = (1.0 / Norm(from)) * from;
  const Vec3 t = (1.0 / Norm(to)) * to;
  const Vec3 axis = Cross(f, t);
  const double sin_angle = Norm(axis);
  const double cos_angle = std::clamp(Dot(f, t), -1.0, 1.0);
  if (sin_angle < 1e-12) {
    if (cos_angle > 0) return Mat3::Identity();
    // Opposite directions: half turn about any axis orthogonal to f.
    const Vec3 helper = std::abs(f.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
    const Vec3 ortho = Cross(f, helper);
    return AxisAngleToMatrix((kPi / Norm(ortho)) * ortho);
  }
  const double angle = std::atan2(sin_angle, cos_angle);
  return AxisAngleToMatrix((angle / sin_angle) * axis);
}

namespace {
// Orthonormal frame (columns) from a primary direction and a secondary hint.
Mat3 FrameFrom(const Vec3& primary, const Vec3& secondary) {
  const Vec3 e0 = (1.0 / Norm(primary)) * primary;
  Vec3 e1 = secondary - Dot(secondary, e0) * e0;
  e1 = (1.0 / Norm(e1)) * e1;
  const Vec3 e2 = Cross(e0, e1);
  Mat3 f;
  f.m = {{{e0.x, e1.x, e2.x}, {e0.y, e1.y, e2.y}, {e0.z, e1.z, e2.z}}};
  return f;
}
}  // namespace

Mat3 RotationFromTwoDirections(const Vec3& from_primary, const Vec3& from_secondary,
                               const Vec3& to_primary, const Vec3& to_secondary) {
  return FrameFrom(to_primary, to_secondary) * Transpose(FrameFrom(from_primary, from_secondary));
}

}  // namespace motionpipe
