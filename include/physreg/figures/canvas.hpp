// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A small raster canvas for the figures physreg writes (slices, charts): pixels, lines, markers
// and a 5×7 bitmap font. Hand-written: the Debian plotting libraries (e.g. VTK, Cairo) are heavy
// for what amounts to a few hundred pixels of annotation.
#include "physreg/io/png.hpp"

#include <array>
#include <string>

namespace physreg {

using Rgb = std::array<std::uint8_t, 3>;

class Canvas {
public:
    Canvas(int width, int height, Rgb background = {255, 255, 255});
    int width() const { return m_image.width; }
    int height() const { return m_image.height; }
    void set(int x, int y, Rgb colour); ///< ignores pixels outside
    Rgb get(int x, int y) const;
    void fill_rect(int x0, int y0, int x1, int y1, Rgb colour); ///< inclusive corners
    void line(double x0, double y0, double x1, double y1, Rgb colour, int thickness = 1);
    void circle(double cx, double cy, double radius, Rgb colour);
    void cross(double cx, double cy, int half_size, Rgb colour, int thickness = 1);
    /// Text in a 5×7 font (upper case, digits, ". , : - + / ( ) % = _ < >"); `scale` ≥ 1.
    void text(int x, int y, const std::string& text, Rgb colour, int scale = 1);
    static int text_width(const std::string& text, int scale = 1) { return static_cast<int>(text.size()) * 6 * scale; }
    /// Pastes another canvas with its top-left corner at (x, y).
    void paste(const Canvas& other, int x, int y);
    const RgbImage& image() const { return m_image; }

private:
    RgbImage m_image;
};

} // namespace physreg
