// A small RGB raster for plots and previews: anti-aliased lines and discs, rectangles, a built-in
// 5x7 bitmap font, and PNG output (zlib). No external image library.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::render {

struct Color {
  uint8_t r = 0, g = 0, b = 0;
};

inline constexpr Color kWhite{255, 255, 255};
inline constexpr Color kBlack{0, 0, 0};
inline constexpr Color kGrey{128, 128, 128};
inline constexpr Color kLightGrey{220, 220, 220};
// A colour-blind-safe categorical palette (Okabe-Ito).
inline constexpr Color kPalette[] = {{0, 114, 178},  {230, 159, 0}, {0, 158, 115},  {204, 121, 167},
                                     {86, 180, 233}, {213, 94, 0},  {240, 228, 66}, {0, 0, 0}};

class Image {
 public:
  Image(int width, int height, Color background = kWhite);

  int width() const { return width_; }
  int height() const { return height_; }
  Color At(int x, int y) const;
  // Blends `c` over the pixel with coverage alpha in [0, 1]; outside the image is ignored.
  void Blend(int x, int y, Color c, double alpha);
  void FillRect(double x0, double y0, double x1, double y1, Color c, double alpha = 1.0);
  void StrokeRect(double x0, double y0, double x1, double y1, Color c, double width = 1.0);
  // Anti-aliased segment of the given width (pixels); `dash` > 0 draws dashes of that length.
  void Line(double x0, double y0, double x1, double y1, Color c, double width = 1.0,
            double dash = 0);
  void Polyline(const std::vector<double>& xs, const std::vector<double>& ys, Color c,
                double width = 1.0);
  void Disc(double cx, double cy, double radius, Color c, double alpha = 1.0);

  // Text in the built-in font, `scale` pixels per font pixel; (x, y) is the top-left corner.
  // `vertical` draws bottom-to-top (axis labels). Characters outside printable ASCII show as '?'.
  void Text(double x, double y, std::string_view text, Color c, int scale = 2,
            bool vertical = false);
  static int TextWidth(std::string_view text, int scale = 2) {
    return static_cast<int>(text.size()) * 6 * scale;
  }
  static int TextHeight(int scale = 2) { return 7 * scale; }

  // PNG (8-bit RGB, zlib level 6). Deterministic bytes.
  std::string EncodePng() const;
  Status WritePng(const std::string& path) const;                 // atomic
  const std::vector<uint8_t>& pixels() const { return pixels_; }  // RGB rows, top to bottom

 private:
  int width_, height_;
  std::vector<uint8_t> pixels_;
};

// Reads a PNG written by EncodePng (8-bit RGB, non-interlaced) back: for tests and for checking
// rendered previews. DataLoss names `origin`.
Result<Image> DecodePng(std::string_view bytes, const std::string& origin);

}  // namespace motionpipe::render
