// Skeleton animations of motions (`motionpipe render`, the report's previews): each motion in its
// own panel, seen from a camera that follows the pelvis at a fixed azimuth and elevation, over a
// floor grid fixed in the world (so that walking shows), bones coloured by body part (left warm,
// right cool), a caption per panel. Output as an animated GIF or a PNG film strip of evenly spaced
// frames.
#pragma once

#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/render/image.h"

namespace motionpipe::render {

struct MotionPanel {
  Motion motion;
  std::string title;    // first caption line (e.g. "source", "edited", "SINC")
  std::string caption;  // second line (e.g. the text; composed motions: "walk forward + wave")
};

struct RenderOptions {
  int panel_width = 320, panel_height = 320;
  double azimuth_degrees = 35, elevation_degrees = 18;
  double distance = 4.0;  // metres from the followed pelvis
  double fps = 15;        // GIF frame rate (motions are resampled by frame picking)
  int strip_frames = 6;   // PNG: frames per panel
};

// One frame: every panel at time `seconds` (a panel past its end shows its last frame).
Image RenderFrame(const std::vector<MotionPanel>& panels, double seconds,
                  const RenderOptions& options);

// An animated GIF (looping) or, for a path ending in .png, a film strip (panels as rows). Atomic.
Status RenderMotionFile(const std::string& path, const std::vector<MotionPanel>& panels,
                        const RenderOptions& options = {});

// GIF89a bytes of frames of equal size, `delay_cs` hundredths of a second each, looping forever.
// Colours are quantised to a 6x6x6 cube plus 40 greys.
std::string EncodeGif(const std::vector<Image>& frames, int delay_cs);

}  // namespace motionpipe::render
