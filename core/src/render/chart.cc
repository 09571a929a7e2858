#include "motionpipe/render/chart.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace motionpipe::render {

namespace {
constexpr int kScale = 2;  // font pixels
constexpr Color kAxis{40, 40, 40};
constexpr Color kGrid{232, 232, 232};
}  // namespace

std::string TickLabel(double value) {
  char text[32];
  const double a = std::fabs(value);
  if (a >= 1 && a < 1e7 && value == std::round(value)) {
    std::snprintf(text, sizeof text, "%.0f", value);
  } else if (a != 0 && (a >= 1e5 || a < 1e-3)) {
    std::snprintf(text, sizeof text, "%.0e", value);
  } else {
    std::snprintf(text, sizeof text, "%.4g", value);
  }
  return text;
}

std::vector<double> NiceTicks(double lo, double hi, int count) {
  std::vector<double> ticks;
  if (!(hi > lo) || count < 1) return {lo};
  const double raw = (hi - lo) / count;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  double step = magnitude;
  for (const double m : {1.0, 2.0, 2.5, 5.0, 10.0}) {
    step = m * magnitude;
    if (step >= raw) break;
  }
  for (double t = std::ceil(lo / step - 1e-9) * step; t <= hi + step * 1e-9; t += step)
    ticks.push_back(std::fabs(t) < step * 1e-9 ? 0.0 : t);
  return ticks;
}

Panel::Panel(Image* image, int x, int y, int width, int height)
    : image_(image), x_(x), y_(y), width_(width), height_(height) {
  left_ = x + 26 + 7 * 6 * kScale / 2 + 14;
  right_ = x + width - 14;
  top_ = y + 12 + Image::TextHeight(kScale) + 10;
  bottom_ = y + height - (14 + 2 * Image::TextHeight(kScale) + 12);
}

void Panel::SetLimits(double x_min, double x_max, double y_min, double y_max, bool log_x) {
  x_min_ = x_min, x_max_ = x_max > x_min ? x_max : x_min + 1;
  y_min_ = y_min, y_max_ = y_max > y_min ? y_max : y_min + 1;
  log_x_ = log_x && x_min > 0;
  // Room on the left for the widest y tick label and the vertical axis label.
  int widest = 0;
  for (const double t : NiceTicks(y_min_, y_max_, 5))
    widest = std::max(widest, Image::TextWidth(TickLabel(t), kScale));
  left_ = x_ + 8 + Image::TextHeight(kScale) + 10 + widest + 10;
}

double Panel::PixelX(double x) const {
  double t;
  if (log_x_) {
    t = (std::log10(std::max(x, 1e-300)) - std::log10(x_min_)) /
        (std::log10(x_max_) - std::log10(x_min_));
  } else {
    t = (x - x_min_) / (x_max_ - x_min_);
  }
  return left_ + t * (right_ - left_);
}

double Panel::PixelY(double y) const {
  return bottom_ - (y - y_min_) / (y_max_ - y_min_) * (bottom_ - top_);
}

void Panel::DrawAxes() {
  image_->Text(x_ + (width_ - Image::TextWidth(title_, kScale)) / 2.0, y_ + 10, title_, kBlack,
               kScale);
  // y grid and ticks
  for (const double t : NiceTicks(y_min_, y_max_, 5)) {
    const double py = PixelY(t);
    image_->Line(left_, py, right_, py, kGrid, 1.0);
    image_->Line(left_ - 5, py, left_, py, kAxis, 1.0);
    const std::string label = TickLabel(t);
    image_->Text(left_ - 8 - Image::TextWidth(label, kScale), py - Image::TextHeight(kScale) / 2.0,
                 label, kAxis, kScale);
  }
  // x ticks
  std::vector<std::pair<double, std::string>> xticks;
  if (!categories_.empty()) {
    for (size_t k = 0; k < categories_.size(); ++k)
      xticks.emplace_back(static_cast<double>(k), categories_[k]);
  } else if (log_x_) {
    for (double decade = std::pow(10.0, std::floor(std::log10(x_min_))); decade <= x_max_ * 1.0001;
         decade *= 10) {
      for (const double m : {1.0, 2.0, 5.0}) {
        const double t = m * decade;
        if (t >= x_min_ * 0.9999 && t <= x_max_ * 1.0001) xticks.emplace_back(t, TickLabel(t));
      }
    }
  } else {
    for (const double t : NiceTicks(x_min_, x_max_, 6)) xticks.emplace_back(t, TickLabel(t));
  }
  for (const auto& [t, label] : xticks) {
    const double px = PixelX(t);
    if (categories_.empty()) image_->Line(px, top_, px, bottom_, kGrid, 1.0);
    image_->Line(px, bottom_, px, bottom_ + 5, kAxis, 1.0);
    image_->Text(px - Image::TextWidth(label, kScale) / 2.0, bottom_ + 9, label, kAxis, kScale);
  }
  image_->StrokeRect(left_, top_, right_, bottom_, kAxis, 1.0);
  image_->Text((left_ + right_ - Image::TextWidth(x_label_, kScale)) / 2.0,
               bottom_ + 14 + Image::TextHeight(kScale), x_label_, kBlack, kScale);
  image_->Text(x_ + 8, (top_ + bottom_ + Image::TextWidth(y_label_, kScale)) / 2.0, y_label_,
               kBlack, kScale, true);
}

void Panel::LinePlot(const std::vector<double>& xs, const std::vector<double>& ys, Color c,
                     double width) {
  std::vector<double> px, py;
  for (size_t k = 0; k < std::min(xs.size(), ys.size()); ++k) {
    px.push_back(PixelX(xs[k]));
    py.push_back(
        std::clamp(PixelY(ys[k]), static_cast<double>(top_), static_cast<double>(bottom_)));
  }
  image_->Polyline(px, py, c, width);
}

void Panel::Bar(double x_left, double x_right, double height, Color c, double alpha) {
  const double base = std::clamp(PixelY(std::max(y_min_, 0.0)), static_cast<double>(top_),
                                 static_cast<double>(bottom_));
  const double top =
      std::clamp(PixelY(height), static_cast<double>(top_), static_cast<double>(bottom_));
  image_->FillRect(PixelX(x_left), top, PixelX(x_right), base, c, alpha);
}

void Panel::VerticalLine(double x, Color c, double width, double dash) {
  image_->Line(PixelX(x), top_, PixelX(x), bottom_, c, width, dash);
}

void Panel::HorizontalLine(double y, Color c, double width, double dash) {
  image_->Line(left_, PixelY(y), right_, PixelY(y), c, width, dash);
}

void Panel::ShadeX(double x0, double x1, Color c, double alpha) {
  image_->FillRect(std::max<double>(left_, PixelX(x0)), top_, std::min<double>(right_, PixelX(x1)),
                   bottom_, c, alpha);
}

void Panel::Legend(const std::vector<std::pair<std::string, Color>>& entries) {
  int widest = 0;
  for (const auto& entry : entries)
    widest = std::max(widest, Image::TextWidth(entry.first, kScale));
  const int line = Image::TextHeight(kScale) + 6;
  const double x0 = right_ - widest - 44, y0 = top_ + 8;
  image_->FillRect(x0 - 6, y0 - 6, right_ - 6, y0 + line * static_cast<double>(entries.size()),
                   kWhite, 0.85);
  for (size_t k = 0; k < entries.size(); ++k) {
    const double y = y0 + line * static_cast<double>(k);
    image_->FillRect(x0, y + 2, x0 + 22, y + Image::TextHeight(kScale) - 2, entries[k].second);
    image_->Text(x0 + 30, y, entries[k].first, kBlack, kScale);
  }
}

void Panel::Note(const std::vector<std::string>& lines, Color c) {
  const int line = Image::TextHeight(kScale) + 6;
  for (size_t k = 0; k < lines.size(); ++k)
    image_->Text(left_ + 10, top_ + 10 + line * static_cast<double>(k), lines[k], c, kScale);
}

}  // namespace motionpipe::render
