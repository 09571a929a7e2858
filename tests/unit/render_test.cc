// The raster used for plots and previews: drawing, text, PNG round trip.
#include <gtest/gtest.h>

#include "motionpipe/render/chart.h"
#include "motionpipe/render/image.h"

namespace motionpipe::render {
namespace {

int CountNonWhite(const Image& image, int x0, int y0, int x1, int y1) {
  int n = 0;
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      const Color c = image.At(x, y);
      n += (c.r != 255 || c.g != 255 || c.b != 255) ? 1 : 0;
    }
  }
  return n;
}

TEST(Image, PngRoundTripIsExact) {
  Image image(37, 23);
  image.FillRect(3, 4, 20, 15, {200, 10, 30});
  image.Line(0, 0, 36, 22, kPalette[0], 2.0);
  image.Disc(30, 5, 3, kPalette[2]);
  const std::string png = image.EncodePng();
  EXPECT_EQ(png.substr(1, 3), "PNG");
  auto back = DecodePng(png, "t.png");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->width(), 37);
  ASSERT_EQ(back->height(), 23);
  EXPECT_EQ(back->pixels(), image.pixels());
  std::string damaged = png;
  damaged[png.size() / 2] ^= 0x40;
  EXPECT_FALSE(DecodePng(damaged, "d.png").ok());
  EXPECT_FALSE(DecodePng("GIF89a", "x.gif").ok());
}

TEST(Image, DrawingTouchesTheRightPixels) {
  Image image(100, 100);
  image.FillRect(10, 10, 20, 20, kBlack);
  EXPECT_EQ(image.At(15, 15).r, 0);
  EXPECT_EQ(image.At(25, 25).r, 255);
  image.Line(50, 10, 50, 90, kBlack, 3.0);
  EXPECT_EQ(image.At(50, 50).r, 0);
  EXPECT_EQ(image.At(55, 50).r, 255);
  // Half coverage at a rectangle edge blends half way.
  Image half(4, 4);
  half.FillRect(0, 0, 2.5, 4, kBlack);
  EXPECT_NEAR(half.At(2, 1).r, 128, 1);
}

TEST(Image, TextIsDrawnAndDistinctGlyphsDiffer) {
  Image a(200, 40), b(200, 40);
  a.Text(5, 5, "MotionSNR 2.5", kBlack, 2);
  b.Text(5, 5, "MotionSNR 3.5", kBlack, 2);
  EXPECT_GT(CountNonWhite(a, 0, 0, 200, 40), 100);
  EXPECT_NE(a.pixels(), b.pixels());
  // Spaces draw nothing; characters outside ASCII become '?'.
  Image space(40, 20), question(40, 20), unicode(40, 20);
  space.Text(2, 2, "   ", kBlack);
  EXPECT_EQ(CountNonWhite(space, 0, 0, 40, 20), 0);
  question.Text(2, 2, "?", kBlack);
  unicode.Text(2, 2, "\xc3", kBlack);
  EXPECT_EQ(question.pixels(), unicode.pixels());
  EXPECT_EQ(Image::TextWidth("abc", 2), 36);
}

TEST(Chart, TicksAndLabels) {
  const auto unit = NiceTicks(0, 1, 5);
  ASSERT_EQ(unit.size(), 6u);
  for (size_t k = 0; k < unit.size(); ++k)
    EXPECT_NEAR(unit[k], 0.2 * static_cast<double>(k), 1e-12);
  const auto ticks = NiceTicks(0, 48000, 5);
  EXPECT_EQ(ticks.front(), 0);
  EXPECT_EQ(ticks[1], 10000);
  EXPECT_EQ(TickLabel(40000), "40000");
  EXPECT_EQ(TickLabel(0.25), "0.25");
  EXPECT_EQ(TickLabel(2e-5), "2e-05");
  Image image(400, 300);
  Panel panel(&image, 0, 0, 400, 300);
  panel.SetTitle("t");
  panel.SetLabels("x", "y");
  panel.SetLimits(0, 10, 0, 1);
  panel.DrawAxes();
  panel.LinePlot({0, 10}, {0, 1}, kPalette[0], 2);
  EXPECT_LT(panel.PixelX(0), panel.PixelX(10));
  EXPECT_GT(panel.PixelY(0), panel.PixelY(1));
  // The line passes through the middle of the plot: pixels there carry its colour.
  const int cx = static_cast<int>(panel.PixelX(5)), cy = static_cast<int>(panel.PixelY(0.5));
  int blue = 0;
  for (int y = cy - 2; y <= cy + 2; ++y) {
    for (int x = cx - 2; x <= cx + 2; ++x)
      blue += image.At(x, y).r < 100 && image.At(x, y).b > 100 ? 1 : 0;
  }
  EXPECT_GT(blue, 2);
}

}  // namespace
}  // namespace motionpipe::render
