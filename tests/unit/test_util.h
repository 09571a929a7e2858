// Shared helpers for the unit tests: deterministic motions and paths to the shipped data.
#pragma once

#include <cmath>
#include <random>
#include <string>

#include "motionpipe/motion/motion.h"

namespace motionpipe::testing {

// The repository's data/ folder (set by CMake).
inline std::string DataDir() { return MOTIONPIPE_DATA_DIR; }
inline std::string SourceDir() { return MOTIONPIPE_SOURCE_DIR; }

// A smooth, non-trivial motion: every joint oscillates about a random axis, the body turns and
// walks along a curve. Deterministic for a seed.
inline Motion SmoothMotion(int64_t frames, uint32_t seed, double fps = 30) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1, 1);
  Motion motion = Motion::Rest(frames, fps, 0.9);
  struct Wave {
    Vec3 axis;
    double amplitude, frequency, phase;
  };
  std::vector<Wave> waves;
  for (int joint = 0; joint < kNumJoints; ++joint) {
    Vec3 axis{unit(rng), unit(rng), unit(rng)};
    axis = (1.0 / Norm(axis)) * axis;
    waves.push_back(
        {axis, 0.2 + 0.6 * std::abs(unit(rng)), 0.3 + std::abs(unit(rng)), 3 * unit(rng)});
  }
  const double heading0 = 3 * unit(rng);
  for (int64_t frame = 0; frame < frames; ++frame) {
    const double t = static_cast<double>(frame) / fps;
    for (int joint = 0; joint < kNumJoints; ++joint) {
      const Wave& w = waves[static_cast<size_t>(joint)];
      const double angle = w.amplitude * std::sin(2 * kPi * w.frequency * t + w.phase);
      Mat3 r = AxisAngleToMatrix(angle * w.axis);
      if (joint == 0)
        r = RotZ(heading0 + 0.8 * t) * YUpToZUp() * AxisAngleToMatrix((0.3 * angle) * w.axis);
      motion.SetLocalRotation(frame, joint, r);
    }
    motion.SetTranslation(frame,
                          {1.0 + 0.9 * t * std::cos(0.4 * t), -2.0 + 0.7 * t * std::sin(0.5 * t),
                           0.9 + 0.05 * std::sin(4 * t)});
  }
  return motion;
}

}  // namespace motionpipe::testing
