// SPDX-License-Identifier: GPL-3.0-or-later
// figures/ against hand-computed pixels (issue 43 item 5): the canvas's rectangles, clipping and
// pasting, and the TRE chart's bar heights (error / axis top × plot height).
#include "physreg/figures/canvas.hpp"
#include "physreg/figures/tre_chart.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

namespace physreg {
namespace {

std::size_t count(const RgbImage& image, Rgb colour)
{
    std::size_t n = 0;
    for (std::size_t p = 0; p + 2 < image.rgb.size(); p += 3)
        n += image.rgb[p] == colour[0] && image.rgb[p + 1] == colour[1] && image.rgb[p + 2] == colour[2];
    return n;
}

} // namespace

TEST(Figures, CanvasRectanglesClipAndPaste)
{
    Canvas c(10, 8);
    const Rgb red{255, 0, 0}, blue{0, 0, 255};
    c.fill_rect(2, 3, 4, 5, red); // inclusive corners: 3 × 3 pixels
    EXPECT_EQ(count(c.image(), red), 9u);
    c.fill_rect(8, 6, 20, 20, red); // clipped to the canvas: 2 × 2
    EXPECT_EQ(count(c.image(), red), 13u);
    c.set(-1, 0, blue);
    c.set(10, 0, blue); // outside: ignored
    EXPECT_EQ(count(c.image(), blue), 0u);
    EXPECT_EQ(c.get(3, 4), red);
    Canvas small(2, 2, blue);
    c.paste(small, 0, 0);
    EXPECT_EQ(count(c.image(), blue), 4u);
    EXPECT_EQ(Canvas::text_width("ABC", 2), 36);
}

TEST(Figures, TreChartBarsAreAsTallAsTheirErrors)
{
    // One series: a surface landmark 2 mm off, a tumour 4 mm off. The axis tops at ceil(1.1 × 4) =
    // 5 mm over 320 pixels, so the bars stand 128 and 256 pixels (+1 for the inclusive corner) above
    // the axis; each is (560 / 2 − 4) − 1 = 275 pixels wide (640-pixel chart, 60 + 20 margins).
    const LandmarkSet truth{{"S", Vec3(0, 0, 0), LandmarkType::surface}, {"T", Vec3(0, 10, 0), LandmarkType::tumour}};
    const LandmarkSet predicted{{"S", Vec3(2, 0, 0), LandmarkType::surface}, {"T", Vec3(0, 14, 0), LandmarkType::tumour}};
    const RgbImage chart = render_tre_chart({{"model", compute_tre(predicted, truth, "chart")}}, "TRE");
    EXPECT_EQ(chart.width, 640);
    EXPECT_EQ(chart.height, 50 + 320 + 86);
    EXPECT_EQ(count(chart, Rgb{40, 160, 60}), 275u * 129u);  // surface green
    EXPECT_EQ(count(chart, Rgb{210, 50, 40}), 275u * 257u);  // tumour red
    // A second series is drawn lighter beside the first; series of different lengths are refused.
    const LandmarkSet one{{"S", Vec3(1, 0, 0), LandmarkType::surface}};
    const LandmarkSet one_truth{{"S", Vec3(0, 0, 0), LandmarkType::surface}};
    EXPECT_NE(test::error_message([&] {
                  render_tre_chart({{"a", compute_tre(predicted, truth, "a")}, {"b", compute_tre(one, one_truth, "b")}}, "X");
              }).find("series 'b' has 1 landmarks, the first has 2"),
              std::string::npos);
    EXPECT_NE(test::error_message([&] { render_tre_chart({}, "X"); }).find("nothing to draw"), std::string::npos);
}

} // namespace physreg
