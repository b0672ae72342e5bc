// SPDX-License-Identifier: GPL-3.0-or-later
// Signed distance maps with ITK's exact (Maurer) Euclidean distance transform.
#include "physreg/image/distance_map.hpp"

#include "physreg/core/error.hpp"

#include <itkImage.h>
#include <itkImportImageFilter.h>
#include <itkSignedMaurerDistanceMapImageFilter.h>

#include <algorithm>
#include <cmath>

namespace physreg {

SignedDistanceMap::SignedDistanceMap(const LabelVolume& labels, const std::set<std::int32_t>& region, const std::string& what)
    : m_geometry(labels.geometry)
{
    m_geometry.validate(what);
    if (labels.labels.size() != static_cast<std::size_t>(m_geometry.voxel_count()))
        fail("{}: label volume has {} voxels, its geometry {}", what, labels.labels.size(), m_geometry.voxel_count());
    using Mask = itk::Image<unsigned char, 3>;
    using Distance = itk::Image<float, 3>;
    auto mask = Mask::New();
    Mask::RegionType extent;
    Mask::SpacingType spacing;
    Mask::PointType origin;
    Mask::DirectionType direction;
    for (unsigned a = 0; a < 3; ++a) {
        extent.SetSize(a, static_cast<itk::SizeValueType>(m_geometry.size[a]));
        spacing[a] = m_geometry.spacing[a];
        origin[a] = m_geometry.origin[a];
        for (unsigned b = 0; b < 3; ++b) direction[a][b] = m_geometry.direction(a, b);
    }
    mask->SetRegions(extent);
    mask->SetSpacing(spacing);
    mask->SetOrigin(origin);
    mask->SetDirection(direction);
    mask->Allocate();
    std::size_t inside = 0;
    unsigned char* out = mask->GetBufferPointer();
    for (std::size_t v = 0; v < labels.labels.size(); ++v) {
        out[v] = region.count(labels.labels[v]) ? 1 : 0;
        inside += out[v];
    }
    if (inside == 0) fail("{}: the region is empty (no voxel carries its label)", what);
    if (inside == labels.labels.size()) fail("{}: the region fills the whole image (it has no boundary)", what);

    // Outside the region: the distance to the nearest region voxel centre; inside: to the nearest
    // voxel centre outside it — each the positive side of a Maurer transform (of the region and of
    // its complement), both exact. The interface lies half a voxel from either centre.
    const auto positive_side = [&](bool complement) {
        auto input = Mask::New();
        input->CopyInformation(mask);
        input->SetRegions(extent);
        input->Allocate();
        unsigned char* in = input->GetBufferPointer();
        for (std::size_t v = 0; v < labels.labels.size(); ++v) in[v] = complement ? 1 - out[v] : out[v];
        auto filter = itk::SignedMaurerDistanceMapImageFilter<Mask, Distance>::New();
        filter->SetInput(input);
        filter->SetUseImageSpacing(true);
        filter->SetSquaredDistance(false);
        filter->SetInsideIsPositive(false);
        filter->SetBackgroundValue(0);
        filter->Update();
        const float* d = filter->GetOutput()->GetBufferPointer();
        return std::vector<float>(d, d + labels.labels.size());
    };
    const std::vector<float> to_region = positive_side(false), to_outside = positive_side(true);
    const float half = static_cast<float>(0.5 * m_geometry.spacing.minCoeff());
    m_values.resize(labels.labels.size());
    for (std::size_t v = 0; v < m_values.size(); ++v) m_values[v] = out[v] ? -(to_outside[v] - half) : to_region[v] - half;
    m_index_to_physical_gradient = m_geometry.direction * m_geometry.spacing.cwiseInverse().asDiagonal();
}

double SignedDistanceMap::value(const Vec3& x) const
{
    Vec3 g;
    return value_and_gradient(x, g);
}

double SignedDistanceMap::value_and_gradient(const Vec3& x, Vec3& gradient) const
{
    const Vec3 index = m_geometry.physical_to_index(x);
    // Clamp to the image box; outside, add the distance to the box (gradient pointing away).
    Vec3 clamped;
    for (int a = 0; a < 3; ++a) clamped[a] = std::clamp(index[a], 0.0, static_cast<double>(m_geometry.size[a] - 1));
    const Vec3 beyond_mm = m_geometry.direction * (index - clamped).cwiseProduct(m_geometry.spacing);
    std::int64_t base[3];
    double t[3];
    for (int a = 0; a < 3; ++a) {
        const double floor = std::floor(clamped[a]);
        base[a] = std::min<std::int64_t>(static_cast<std::int64_t>(floor), std::max<std::int64_t>(m_geometry.size[a] - 2, 0));
        t[a] = clamped[a] - static_cast<double>(base[a]);
    }
    double value = 0.0;
    Vec3 grad_index = Vec3::Zero();
    for (int corner = 0; corner < 8; ++corner) {
        const int c[3] = {corner & 1, (corner >> 1) & 1, (corner >> 2) & 1};
        std::int64_t ijk[3];
        double w[3], dw[3];
        for (int a = 0; a < 3; ++a) {
            ijk[a] = std::min<std::int64_t>(base[a] + c[a], m_geometry.size[a] - 1);
            w[a] = c[a] ? t[a] : 1.0 - t[a];
            dw[a] = c[a] ? 1.0 : -1.0;
        }
        const double f = m_values[static_cast<std::size_t>(m_geometry.linear_index(ijk[0], ijk[1], ijk[2]))];
        value += w[0] * w[1] * w[2] * f;
        grad_index[0] += dw[0] * w[1] * w[2] * f;
        grad_index[1] += w[0] * dw[1] * w[2] * f;
        grad_index[2] += w[0] * w[1] * dw[2] * f;
    }
    // Clamped axes: the edge value does not change along them; the distance to the box does.
    for (int a = 0; a < 3; ++a)
        if (index[a] != clamped[a]) grad_index[a] = 0.0;
    gradient = m_index_to_physical_gradient * grad_index;
    const double out = beyond_mm.norm();
    if (out > 0.0) {
        gradient += beyond_mm / out;
        value += out;
    }
    return value;
}

} // namespace physreg
