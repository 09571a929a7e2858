#include "motionpipe/render/motion_render.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "motionpipe/base/file.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::render {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Bone colours by body part: global/torso grey-blue, left arm/leg warm, right arm/leg cool.
Color PartColor(BodyPart part) {
  switch (part) {
    case BodyPart::kLeftArm:
      return {213, 94, 0};
    case BodyPart::kLeftLeg:
      return {230, 159, 0};
    case BodyPart::kRightArm:
      return {0, 114, 178};
    case BodyPart::kRightLeg:
      return {86, 180, 233};
    default:
      return {70, 70, 90};
  }
}

struct Camera {
  double tx, ty, tz;  // followed point
  double ca, sa, ce, se, distance, focal;
  int cx, cy;
  // World (z-up) -> screen x, y and depth (larger = farther).
  void Project(double x, double y, double z, double* sx, double* sy, double* depth) const {
    x -= tx, y -= ty, z -= tz;
    // Rotate about z by the azimuth; the camera then looks along +y' tilted down by the elevation:
    // view direction (0, cos el, -sin el), screen up (0, sin el, cos el).
    const double xr = ca * x + sa * y;
    const double yr = -sa * x + ca * y;
    const double forward = ce * yr - se * z + distance;  // distance along the view axis
    const double up = se * yr + ce * z;
    const double f = focal / std::max(0.1, forward);
    *sx = cx + xr * f;
    *sy = cy - up * f;
    *depth = forward;
  }
};

void DrawPanelAt(Image* image, int x0, int y0, const MotionPanel& panel,
                 const std::vector<float>& joints, double seconds, const RenderOptions& o) {
  const int w = o.panel_width, h = o.panel_height;
  const int64_t frames = panel.motion.num_frames();
  if (frames == 0) return;
  const int64_t f = std::clamp<int64_t>(
      static_cast<int64_t>(std::floor(seconds * panel.motion.fps)), 0, frames - 1);
  // The camera follows the pelvis, smoothed over +-0.5 s so that it does not shake.
  const int64_t half = std::max<int64_t>(1, static_cast<int64_t>(panel.motion.fps / 2));
  double px = 0, py = 0;
  int64_t count = 0;
  for (int64_t k = std::max<int64_t>(0, f - half); k <= std::min(frames - 1, f + half);
       ++k, ++count) {
    px += joints[static_cast<size_t>(k * 66)];
    py += joints[static_cast<size_t>(k * 66 + 1)];
  }
  px /= static_cast<double>(count), py /= static_cast<double>(count);
  const double az = o.azimuth_degrees * kPi / 180, el = o.elevation_degrees * kPi / 180;
  Camera cam{px,           py,         0.9,     std::cos(az), std::sin(az),    std::cos(el),
             std::sin(el), o.distance, 1.1 * h, x0 + w / 2,   y0 + h * 11 / 20};
  // Floor grid: 0.5 m lines fixed in the world, within 3 m of the followed point.
  const double step = 0.5, reach = 3.0;
  const double gx0 = std::floor((px - reach) / step) * step,
               gy0 = std::floor((py - reach) / step) * step;
  for (double g = 0; g <= 2 * reach + 1e-9; g += step) {
    double ax, ay, ad, bx, by, bd;
    cam.Project(gx0 + g, gy0, 0, &ax, &ay, &ad);
    cam.Project(gx0 + g, gy0 + 2 * reach, 0, &bx, &by, &bd);
    if (ad > 1.0 && bd > 1.0) image->Line(ax, ay, bx, by, kLightGrey, 1.0);
    cam.Project(gx0, gy0 + g, 0, &ax, &ay, &ad);
    cam.Project(gx0 + 2 * reach, gy0 + g, 0, &bx, &by, &bd);
    if (ad > 1.0 && bd > 1.0) image->Line(ax, ay, bx, by, kLightGrey, 1.0);
  }
  // Shadow of the pelvis on the floor, then the bones far to near.
  const Skeleton& skeleton = Skeleton::Smpl22();
  const float* j = joints.data() + f * 66;
  double sx, sy, sd;
  cam.Project(j[0], j[1], 0, &sx, &sy, &sd);
  image->Disc(sx, sy, 6, kGrey, 0.35);
  std::vector<int> order(kNumJoints - 1);
  std::iota(order.begin(), order.end(), 1);
  std::vector<double> depth(kNumJoints);
  std::vector<double> xs(kNumJoints), ys(kNumJoints);
  for (int k = 0; k < kNumJoints; ++k)
    cam.Project(j[3 * k], j[3 * k + 1], j[3 * k + 2], &xs[static_cast<size_t>(k)],
                &ys[static_cast<size_t>(k)], &depth[static_cast<size_t>(k)]);
  const auto& parents = skeleton.parents();
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return depth[static_cast<size_t>(a)] +
               depth[static_cast<size_t>(parents[static_cast<size_t>(a)])] >
           depth[static_cast<size_t>(b)] +
               depth[static_cast<size_t>(parents[static_cast<size_t>(b)])];
  });
  for (int k : order) {
    const int p = parents[static_cast<size_t>(k)];
    const Color c = PartColor(skeleton.part_of_joint(k));
    image->Line(xs[static_cast<size_t>(p)], ys[static_cast<size_t>(p)], xs[static_cast<size_t>(k)],
                ys[static_cast<size_t>(k)], c, 4.0);
    image->Disc(xs[static_cast<size_t>(k)], ys[static_cast<size_t>(k)], 2.5, c);
  }
  image->Disc(xs[15], ys[15], 6, PartColor(BodyPart::kTorso));  // the head
  // Captions and the time.
  const auto fit = [&](std::string text) {
    const size_t max_chars = static_cast<size_t>(std::max(4, (w - 8) / 6));
    if (text.size() > max_chars) text = text.substr(0, max_chars - 2) + "..";
    return text;
  };
  image->Text(x0 + 6, y0 + 6, fit(panel.title), kBlack, 2);
  if (!panel.caption.empty()) {
    const size_t max_chars = static_cast<size_t>(std::max(4, (w - 8) / 6));
    std::string rest = panel.caption;
    for (int line = 0; line < 2 && !rest.empty(); ++line) {
      std::string piece = rest.substr(0, max_chars);
      if (rest.size() > max_chars && line == 0) {
        const size_t cut = piece.rfind(' ');
        if (cut != std::string::npos && cut > max_chars / 2) piece = piece.substr(0, cut);
      }
      rest = rest.size() > piece.size() ? rest.substr(piece.size()) : "";
      while (!rest.empty() && rest.front() == ' ') rest.erase(rest.begin());
      if (line == 1 && !rest.empty()) piece = fit(piece + rest);
      image->Text(x0 + 6, y0 + 26 + 10 * line, piece, kGrey, 1);
    }
  }
  char clock[32];
  std::snprintf(clock, sizeof clock, "%.1f s", static_cast<double>(f) / panel.motion.fps);
  image->Text(x0 + w - Image::TextWidth(clock, 1) - 6, y0 + h - 14, clock, kGrey, 1);
  image->StrokeRect(x0 + 0.5, y0 + 0.5, x0 + w - 0.5, y0 + h - 0.5, kLightGrey, 1.0);
}

// Draws a panel clipped to its rectangle: into an image of its own, then copied into place.
void DrawPanel(Image* image, int x0, int y0, const MotionPanel& panel,
               const std::vector<float>& joints, double seconds, const RenderOptions& o) {
  Image own(o.panel_width, o.panel_height);
  DrawPanelAt(&own, 0, 0, panel, joints, seconds, o);
  for (int y = 0; y < own.height(); ++y) {
    for (int x = 0; x < own.width(); ++x) image->Blend(x0 + x, y0 + y, own.At(x, y), 1.0);
  }
}

std::vector<std::vector<float>> JointsOf(const std::vector<MotionPanel>& panels) {
  std::vector<std::vector<float>> joints;
  for (const auto& p : panels) joints.push_back(ComputeJoints(Skeleton::Smpl22(), p.motion));
  return joints;
}

double LongestSeconds(const std::vector<MotionPanel>& panels) {
  double longest = 0;
  for (const auto& p : panels) longest = std::max(longest, p.motion.duration_seconds());
  return longest;
}

// GIF's LZW: variable code sizes from 9 bits, a clear code when the table is full (4096 codes).
class GifLzw {
 public:
  explicit GifLzw(std::string* out) : out_(out) {}
  void Encode(const std::vector<uint8_t>& pixels) {
    std::vector<uint16_t> table(4096 * 256, 0);
    int size = 9, next = 258;
    Write(256, size);
    int current = pixels.empty() ? 0 : pixels[0];
    for (size_t i = 1; i < pixels.size(); ++i) {
      const int value = pixels[i];
      const size_t slot = static_cast<size_t>(current) * 256 + static_cast<size_t>(value);
      if (table[slot]) {
        current = table[slot];
        continue;
      }
      Write(current, size);
      table[slot] = static_cast<uint16_t>(next++);
      if (next > (1 << size)) ++size;
      if (next == 4096) {
        Write(256, size);
        std::fill(table.begin(), table.end(), 0);
        size = 9;
        next = 258;
      }
      current = value;
    }
    Write(current, size);
    Write(256, size);
    Write(257, 9);
    if (bits_ > 0) Byte(static_cast<uint8_t>(buffer_));
    Flush();
    out_->push_back('\0');  // block terminator
  }

 private:
  void Write(int code, int size) {
    buffer_ |= static_cast<uint32_t>(code) << bits_;
    bits_ += size;
    while (bits_ >= 8) {
      Byte(static_cast<uint8_t>(buffer_ & 0xff));
      buffer_ >>= 8;
      bits_ -= 8;
    }
  }
  void Byte(uint8_t b) {
    block_.push_back(static_cast<char>(b));
    if (block_.size() == 255) Flush();
  }
  void Flush() {
    if (block_.empty()) return;
    out_->push_back(static_cast<char>(block_.size()));
    out_->append(block_);
    block_.clear();
  }
  std::string* out_;
  std::string block_;
  uint32_t buffer_ = 0;
  int bits_ = 0;
};

void Put16(std::string* out, int v) {
  out->push_back(static_cast<char>(v & 0xff));
  out->push_back(static_cast<char>((v >> 8) & 0xff));
}

// Palette index of a colour: the 6x6x6 cube (0..215) or, for near-greys, one of 40 greys
// (216..255).
uint8_t Quantize(uint8_t r, uint8_t g, uint8_t b) {
  const int hi = std::max({r, g, b}), lo = std::min({r, g, b});
  if (hi - lo < 12) return static_cast<uint8_t>(216 + std::min(39, (r + g + b) / 3 * 40 / 256));
  const auto level = [](int v) { return (v * 5 + 127) / 255; };
  return static_cast<uint8_t>(36 * level(r) + 6 * level(g) + level(b));
}

}  // namespace

Image RenderFrame(const std::vector<MotionPanel>& panels, double seconds,
                  const RenderOptions& options) {
  const auto joints = JointsOf(panels);
  Image image(options.panel_width * static_cast<int>(std::max<size_t>(1, panels.size())),
              options.panel_height);
  for (size_t k = 0; k < panels.size(); ++k)
    DrawPanel(&image, static_cast<int>(k) * options.panel_width, 0, panels[k], joints[k], seconds,
              options);
  return image;
}

std::string EncodeGif(const std::vector<Image>& frames, int delay_cs) {
  std::string out = "GIF89a";
  const int w = frames.empty() ? 1 : frames[0].width(), h = frames.empty() ? 1 : frames[0].height();
  Put16(&out, w);
  Put16(&out, h);
  out.push_back(static_cast<char>(0xF7));  // global colour table of 256 entries
  out.push_back('\0');
  out.push_back('\0');
  for (int i = 0; i < 256; ++i) {
    int r, g, b;
    if (i < 216) {
      r = i / 36 * 51, g = i / 6 % 6 * 51, b = i % 6 * 51;
    } else {
      r = g = b = (i - 216) * 255 / 39;
    }
    out.push_back(static_cast<char>(r));
    out.push_back(static_cast<char>(g));
    out.push_back(static_cast<char>(b));
  }
  out.append("\x21\xFF\x0BNETSCAPE2.0\x03\x01\x00\x00\x00", 19);  // loop forever
  for (const Image& frame : frames) {
    out.append("\x21\xF9\x04\x04", 4);  // graphic control: disposal "do not dispose"
    Put16(&out, delay_cs);
    out.push_back('\0');
    out.push_back('\0');
    out.push_back(',');  // image descriptor
    Put16(&out, 0);
    Put16(&out, 0);
    Put16(&out, w);
    Put16(&out, h);
    out.push_back('\0');
    out.push_back('\x08');  // LZW minimum code size
    std::vector<uint8_t> indices(static_cast<size_t>(w) * static_cast<size_t>(h));
    const auto& px = frame.pixels();
    for (size_t i = 0; i < indices.size(); ++i)
      indices[i] = Quantize(px[3 * i], px[3 * i + 1], px[3 * i + 2]);
    GifLzw(&out).Encode(indices);
  }
  out.push_back(';');
  return out;
}

Status RenderMotionFile(const std::string& path, const std::vector<MotionPanel>& panels,
                        const RenderOptions& options) {
  if (panels.empty()) return InvalidArgument(path + ": nothing to render");
  for (const auto& p : panels) {
    if (p.motion.num_frames() == 0)
      return InvalidArgument(path + ": '" + p.title + "' has no frames");
  }
  const auto ends_with = [&](const char* suffix) {
    const std::string s = suffix;
    return path.size() >= s.size() && path.compare(path.size() - s.size(), s.size(), s) == 0;
  };
  const double seconds = LongestSeconds(panels);
  const auto joints = JointsOf(panels);
  if (ends_with(".png")) {
    // A film strip: one row per panel, strip_frames evenly spaced frames across.
    const int n = std::max(1, options.strip_frames);
    Image image(options.panel_width * n, options.panel_height * static_cast<int>(panels.size()));
    for (size_t row = 0; row < panels.size(); ++row) {
      for (int k = 0; k < n; ++k) {
        const double t = n == 1 ? 0 : seconds * k / (n - 1);
        DrawPanel(&image, k * options.panel_width, static_cast<int>(row) * options.panel_height,
                  panels[row], joints[row], t, options);
      }
    }
    return image.WritePng(path);
  }
  if (ends_with(".gif")) {
    std::vector<Image> frames;
    const int count = std::max(1, static_cast<int>(std::ceil(seconds * options.fps)));
    for (int k = 0; k < count; ++k) {
      Image image(options.panel_width * static_cast<int>(panels.size()), options.panel_height);
      for (size_t i = 0; i < panels.size(); ++i) {
        DrawPanel(&image, static_cast<int>(i) * options.panel_width, 0, panels[i], joints[i],
                  k / options.fps, options);
      }
      frames.push_back(std::move(image));
    }
    return WriteFileAtomic(
        path, EncodeGif(frames, std::max(2, static_cast<int>(std::lround(100 / options.fps)))));
  }
  if (ends_with(".mp4")) {
    return Unimplemented(
        path + ": mp4 output is not available (no video encoder here); write .gif or .png");
  }
  return InvalidArgument(path + ": the output must end in .gif (animation) or .png (film strip)");
}

}  // namespace motionpipe::render
