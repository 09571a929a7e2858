#include "motionpipe/render/image.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "motionpipe/base/file.h"

namespace motionpipe::render {

namespace {

#include "font5x7.inc"

void Put32(std::string* out, uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8)
    out->push_back(static_cast<char>((v >> shift) & 0xFF));
}

uint32_t Get32(std::string_view s, size_t at) {
  return (uint32_t{static_cast<unsigned char>(s[at])} << 24) |
         (uint32_t{static_cast<unsigned char>(s[at + 1])} << 16) |
         (uint32_t{static_cast<unsigned char>(s[at + 2])} << 8) |
         uint32_t{static_cast<unsigned char>(s[at + 3])};
}

void Chunk(std::string* out, const char* type, const std::string& data) {
  Put32(out, static_cast<uint32_t>(data.size()));
  std::string body(type, 4);
  body += data;
  out->append(body);
  Put32(out, static_cast<uint32_t>(crc32(0L, reinterpret_cast<const Bytef*>(body.data()),
                                         static_cast<uInt>(body.size()))));
}

double Clamp01(double v) { return v < 0 ? 0 : (v > 1 ? 1 : v); }

}  // namespace

Image::Image(int width, int height, Color background)
    : width_(std::max(1, width)),
      height_(std::max(1, height)),
      pixels_(static_cast<size_t>(width_) * height_ * 3) {
  for (size_t k = 0; k < pixels_.size(); k += 3) {
    pixels_[k] = background.r;
    pixels_[k + 1] = background.g;
    pixels_[k + 2] = background.b;
  }
}

Color Image::At(int x, int y) const {
  const size_t k = (static_cast<size_t>(y) * width_ + x) * 3;
  return {pixels_[k], pixels_[k + 1], pixels_[k + 2]};
}

void Image::Blend(int x, int y, Color c, double alpha) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_ || alpha <= 0) return;
  alpha = std::min(alpha, 1.0);
  uint8_t* p = &pixels_[(static_cast<size_t>(y) * width_ + x) * 3];
  const uint8_t src[3] = {c.r, c.g, c.b};
  for (int k = 0; k < 3; ++k)
    p[k] = static_cast<uint8_t>(std::lround(p[k] + (src[k] - p[k]) * alpha));
}

void Image::FillRect(double x0, double y0, double x1, double y1, Color c, double alpha) {
  if (x0 > x1) std::swap(x0, x1);
  if (y0 > y1) std::swap(y0, y1);
  const int ix0 = std::max(0, static_cast<int>(std::floor(x0))),
            ix1 = std::min(width_ - 1, static_cast<int>(std::ceil(x1)));
  const int iy0 = std::max(0, static_cast<int>(std::floor(y0))),
            iy1 = std::min(height_ - 1, static_cast<int>(std::ceil(y1)));
  for (int y = iy0; y <= iy1; ++y) {
    const double cy = Clamp01(std::min(y + 1.0, y1) - std::max(static_cast<double>(y), y0));
    for (int x = ix0; x <= ix1; ++x) {
      const double cx = Clamp01(std::min(x + 1.0, x1) - std::max(static_cast<double>(x), x0));
      Blend(x, y, c, alpha * cx * cy);
    }
  }
}

void Image::StrokeRect(double x0, double y0, double x1, double y1, Color c, double width) {
  Line(x0, y0, x1, y0, c, width);
  Line(x1, y0, x1, y1, c, width);
  Line(x1, y1, x0, y1, c, width);
  Line(x0, y1, x0, y0, c, width);
}

void Image::Line(double x0, double y0, double x1, double y1, Color c, double width, double dash) {
  const double dx = x1 - x0, dy = y1 - y0;
  const double length = std::hypot(dx, dy);
  if (dash > 0 && length > dash) {
    for (double s = 0; s < length; s += 2 * dash) {
      const double e = std::min(length, s + dash);
      Line(x0 + dx * s / length, y0 + dy * s / length, x0 + dx * e / length, y0 + dy * e / length,
           c, width);
    }
    return;
  }
  // Coverage from the distance of each pixel centre to the segment: a capsule of radius width/2,
  // softened over one pixel.
  const double r = width / 2;
  const int xa = static_cast<int>(std::floor(std::min(x0, x1) - r - 1)),
            xb = static_cast<int>(std::ceil(std::max(x0, x1) + r + 1));
  const int ya = static_cast<int>(std::floor(std::min(y0, y1) - r - 1)),
            yb = static_cast<int>(std::ceil(std::max(y0, y1) + r + 1));
  const double len2 = dx * dx + dy * dy;
  for (int y = std::max(0, ya); y <= std::min(height_ - 1, yb); ++y) {
    for (int x = std::max(0, xa); x <= std::min(width_ - 1, xb); ++x) {
      const double px = x + 0.5 - x0, py = y + 0.5 - y0;
      const double t = len2 > 0 ? Clamp01((px * dx + py * dy) / len2) : 0;
      const double d = std::hypot(px - t * dx, py - t * dy);
      Blend(x, y, c, Clamp01(r + 0.5 - d));
    }
  }
}

void Image::Polyline(const std::vector<double>& xs, const std::vector<double>& ys, Color c,
                     double width) {
  for (size_t k = 1; k < std::min(xs.size(), ys.size()); ++k)
    Line(xs[k - 1], ys[k - 1], xs[k], ys[k], c, width);
}

void Image::Disc(double cx, double cy, double radius, Color c, double alpha) {
  for (int y = static_cast<int>(std::floor(cy - radius - 1));
       y <= static_cast<int>(std::ceil(cy + radius + 1)); ++y) {
    for (int x = static_cast<int>(std::floor(cx - radius - 1));
         x <= static_cast<int>(std::ceil(cx + radius + 1)); ++x) {
      const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
      Blend(x, y, c, alpha * Clamp01(radius + 0.5 - d));
    }
  }
}

void Image::Text(double x, double y, std::string_view text, Color c, int scale, bool vertical) {
  scale = std::max(1, scale);
  const int ox = static_cast<int>(std::lround(x)), oy = static_cast<int>(std::lround(y));
  for (size_t k = 0; k < text.size(); ++k) {
    int code = static_cast<unsigned char>(text[k]);
    if (code < 32 || code > 126) code = '?';
    const char* glyph = kGlyphs[code - 32];
    for (int row = 0; row < 7; ++row) {
      for (int col = 0; col < 5; ++col) {
        if (glyph[row * 5 + col] != '#') continue;
        const int gx = static_cast<int>(k) * 6 + col;  // along the text
        for (int sy = 0; sy < scale; ++sy) {
          for (int sx = 0; sx < scale; ++sx) {
            if (vertical) {
              Blend(ox + row * scale + sy, oy - gx * scale - sx, c, 1.0);
            } else {
              Blend(ox + gx * scale + sx, oy + row * scale + sy, c, 1.0);
            }
          }
        }
      }
    }
  }
}

std::string Image::EncodePng() const {
  std::string raw;
  raw.reserve(static_cast<size_t>(height_) * (width_ * 3 + 1));
  for (int y = 0; y < height_; ++y) {
    raw.push_back(0);  // filter: none
    raw.append(reinterpret_cast<const char*>(&pixels_[static_cast<size_t>(y) * width_ * 3]),
               static_cast<size_t>(width_) * 3);
  }
  uLongf size = compressBound(static_cast<uLong>(raw.size()));
  std::string compressed(size, '\0');
  compress2(reinterpret_cast<Bytef*>(compressed.data()), &size,
            reinterpret_cast<const Bytef*>(raw.data()), static_cast<uLong>(raw.size()), 6);
  compressed.resize(size);
  std::string out("\x89PNG\r\n\x1a\n", 8);
  std::string header;
  Put32(&header, static_cast<uint32_t>(width_));
  Put32(&header, static_cast<uint32_t>(height_));
  header +=
      std::string("\x08\x02\x00\x00\x00", 5);  // 8-bit, RGB, deflate, no filter set, no interlace
  Chunk(&out, "IHDR", header);
  Chunk(&out, "IDAT", compressed);
  Chunk(&out, "IEND", "");
  return out;
}

Status Image::WritePng(const std::string& path) const {
  return WriteFileAtomic(path, EncodePng(), false);
}

Result<Image> DecodePng(std::string_view bytes, const std::string& origin) {
  if (bytes.size() < 8 || bytes.substr(0, 8) != std::string_view("\x89PNG\r\n\x1a\n", 8)) {
    return DataLoss(origin + ": not a PNG file");
  }
  size_t at = 8;
  int width = 0, height = 0;
  std::string idat;
  bool ended = false;
  while (at + 12 <= bytes.size() && !ended) {
    const uint32_t length = Get32(bytes, at);
    if (length > bytes.size() - at - 12) return DataLoss(origin + ": PNG chunk runs past the end");
    const std::string_view type = bytes.substr(at + 4, 4);
    const std::string_view data = bytes.substr(at + 8, length);
    const uint32_t crc = Get32(bytes, at + 8 + length);
    if (crc != static_cast<uint32_t>(
                   crc32(0L, reinterpret_cast<const Bytef*>(bytes.data() + at + 4), length + 4))) {
      return DataLoss(origin + ": PNG chunk " + std::string(type) + " fails its CRC");
    }
    if (type == "IHDR") {
      if (length != 13) return DataLoss(origin + ": bad IHDR");
      width = static_cast<int>(Get32(data, 0));
      height = static_cast<int>(Get32(data, 4));
      if (data[8] != 8 || data[9] != 2 || data[12] != 0)
        return DataLoss(origin + ": only 8-bit RGB non-interlaced PNG is read");
      if (width <= 0 || height <= 0 || static_cast<int64_t>(width) * height > (int64_t{1} << 28)) {
        return DataLoss(origin + ": implausible PNG size");
      }
    } else if (type == "IDAT") {
      idat.append(data);
    } else if (type == "IEND") {
      ended = true;
    }
    at += 12 + length;
  }
  if (width == 0 || !ended) return DataLoss(origin + ": PNG is truncated");
  const size_t stride = static_cast<size_t>(width) * 3;
  std::string raw(static_cast<size_t>(height) * (stride + 1), '\0');
  uLongf size = static_cast<uLongf>(raw.size());
  if (uncompress(reinterpret_cast<Bytef*>(raw.data()), &size,
                 reinterpret_cast<const Bytef*>(idat.data()),
                 static_cast<uLong>(idat.size())) != Z_OK ||
      size != raw.size()) {
    return DataLoss(origin + ": PNG image data is corrupt");
  }
  Image image(width, height);
  std::vector<uint8_t> previous(stride, 0), current(stride);
  for (int y = 0; y < height; ++y) {
    const auto* line =
        reinterpret_cast<const uint8_t*>(raw.data() + static_cast<size_t>(y) * (stride + 1));
    const uint8_t filter = line[0];
    for (size_t k = 0; k < stride; ++k) {
      const int a = k >= 3 ? current[k - 3] : 0, b = previous[k], c = k >= 3 ? previous[k - 3] : 0;
      int predictor = 0;
      switch (filter) {
        case 0:
          predictor = 0;
          break;
        case 1:
          predictor = a;
          break;
        case 2:
          predictor = b;
          break;
        case 3:
          predictor = (a + b) / 2;
          break;
        case 4: {
          const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
          predictor = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
          break;
        }
        default:
          return DataLoss(origin + ": unknown PNG filter " + std::to_string(filter));
      }
      current[k] = static_cast<uint8_t>(line[1 + k] + predictor);
    }
    for (int x = 0; x < width; ++x)
      image.Blend(x, y, {current[3 * x], current[3 * x + 1], current[3 * x + 2]}, 1.0);
    std::swap(previous, current);
  }
  return image;
}

}  // namespace motionpipe::render
