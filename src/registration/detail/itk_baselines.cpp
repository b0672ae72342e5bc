// SPDX-License-Identifier: GPL-3.0-or-later
// ITK's rigid, Demons and B-spline registration (paper 002's baselines), behind plain types.
#include "itk_baselines.hpp"

#include "physreg/core/error.hpp"

#include <itkBSplineTransform.h>
#include <itkBSplineTransformInitializer.h>
#include <itkBSplineTransformParametersAdaptor.h>
#include <itkCenteredTransformInitializer.h>
#include <itkCentralDifferenceImageFunction.h>
#include <itkDiffeomorphicDemonsRegistrationFilter.h>
#include <itkHistogramMatchingImageFilter.h>
#include <itkImage.h>
#include <itkImageRegionConstIteratorWithIndex.h>
#include <itkImageRegistrationMethodv4.h>
#include <itkLBFGSBOptimizer.h>
#include <itkLinearInterpolateImageFunction.h>
#include <itkMattesMutualInformationImageToImageMetricv4.h>
#include <itkMeanSquaresImageToImageMetricv4.h>
#include <itkMultiResolutionPDEDeformableRegistration.h>
#include <itkMultiThreaderBase.h>
#include <itkRegularStepGradientDescentOptimizerv4.h>
#include <itkSingleValuedCostFunction.h>
#include <itkSmoothingRecursiveGaussianImageFilter.h>
#include <itkVersorRigid3DTransform.h>


#include <omp.h>

#include <chrono>
#include <cmath>
#include <random>

namespace physreg::detail {
namespace {

using Image = itk::Image<float, 3>;
using Field = itk::Image<itk::Vector<float, 3>, 3>;

Image::Pointer to_itk(const PlainImage& in)
{
    auto image = Image::New();
    Image::RegionType region;
    Image::SpacingType spacing;
    Image::PointType origin;
    Image::DirectionType direction;
    for (unsigned a = 0; a < 3; ++a) {
        region.SetSize(a, static_cast<itk::SizeValueType>(in.geometry.size[a]));
        spacing[a] = in.geometry.spacing[a];
        origin[a] = in.geometry.origin[a];
        for (unsigned b = 0; b < 3; ++b) direction[a][b] = in.geometry.direction[3 * a + b];
    }
    image->SetRegions(region);
    image->SetSpacing(spacing);
    image->SetOrigin(origin);
    image->SetDirection(direction);
    image->Allocate();
    std::copy(in.values.begin(), in.values.end(), image->GetBufferPointer());
    return image;
}

template <typename Transform>
std::vector<float> field_of(const Transform& transform, const Image* fixed)
{
    const auto size = fixed->GetLargestPossibleRegion().GetSize();
    std::vector<float> field(3 * fixed->GetLargestPossibleRegion().GetNumberOfPixels());
    const auto nk = static_cast<std::int64_t>(size[2]);
#pragma omp parallel for schedule(static)
    for (std::int64_t k = 0; k < nk; ++k)
        for (itk::SizeValueType j = 0; j < size[1]; ++j)
            for (itk::SizeValueType i = 0; i < size[0]; ++i) {
                Image::IndexType index;
                index[0] = static_cast<itk::IndexValueType>(i);
                index[1] = static_cast<itk::IndexValueType>(j);
                index[2] = static_cast<itk::IndexValueType>(k);
                typename Transform::InputPointType p;
                fixed->TransformIndexToPhysicalPoint(index, p);
                const auto q = transform.TransformPoint(p);
                const std::size_t v = i + size[0] * (j + size[1] * static_cast<std::size_t>(k));
                for (unsigned a = 0; a < 3; ++a) field[3 * v + a] = static_cast<float>(q[a] - p[a]);
            }
    return field;
}

// The metric's sums are split into a fixed number of work units (added in order), whatever the
// thread count, so that 1 and 2 threads give the same bits.
constexpr itk::ThreadIdType metric_work_units = 8;

itk::SmartPointer<itk::ImageToImageMetricv4<Image, Image>> make_metric(bool mutual_information)
{
    itk::SmartPointer<itk::ImageToImageMetricv4<Image, Image>> metric;
    if (mutual_information) {
        auto mattes = itk::MattesMutualInformationImageToImageMetricv4<Image, Image>::New();
        mattes->SetNumberOfHistogramBins(50);
        metric = mattes.GetPointer();
    } else {
        metric = itk::MeanSquaresImageToImageMetricv4<Image, Image>::New().GetPointer();
    }
    metric->SetMaximumNumberOfWorkUnits(metric_work_units);
    return metric;
}

PlainBaselineResult rigid(const Image::Pointer& fixed, const Image::Pointer& moving, bool labels_mode, const PlainBaselineOptions& o)
{
    using Transform = itk::VersorRigid3DTransform<double>;
    using Optimizer = itk::RegularStepGradientDescentOptimizerv4<double>;
    using Registration = itk::ImageRegistrationMethodv4<Image, Image, Transform>;
    auto transform = Transform::New();
    auto initializer = itk::CenteredTransformInitializer<Transform, Image, Image>::New();
    initializer->SetTransform(transform);
    initializer->SetFixedImage(fixed);
    initializer->SetMovingImage(moving);
    initializer->GeometryOn(); // the same scanner frame: start at the identity about the image centre
    initializer->InitializeTransform();
    transform->SetTranslation(Transform::OutputVectorType(0.0));
    auto optimizer = Optimizer::New();
    Optimizer::ScalesType scales(transform->GetNumberOfParameters());
    for (unsigned p = 0; p < 3; ++p) scales[p] = 1.0;
    for (unsigned p = 3; p < 6; ++p) scales[p] = 1.0 / 1000.0; // rotation (rad) vs translation (mm) over a ≈ 1 m lever
    optimizer->SetScales(scales);
    optimizer->SetLearningRate(0.2);
    optimizer->SetMinimumStepLength(1e-4);
    optimizer->SetRelaxationFactor(0.5);
    optimizer->SetNumberOfIterations(static_cast<itk::SizeValueType>(o.rigid_iterations));
    auto registration = Registration::New();
    registration->SetFixedImage(fixed);
    registration->SetMovingImage(moving);
    registration->SetMetric(make_metric(!labels_mode));
    registration->SetOptimizer(optimizer);
    registration->SetInitialTransform(transform);
    registration->InPlaceOn();
    registration->SetNumberOfLevels(3);
    Registration::ShrinkFactorsArrayType shrink(3);
    shrink[0] = 4;
    shrink[1] = 2;
    shrink[2] = 1;
    registration->SetShrinkFactorsPerLevel(shrink);
    Registration::SmoothingSigmasArrayType sigmas(3);
    sigmas[0] = 2;
    sigmas[1] = 1;
    sigmas[2] = 0;
    registration->SetSmoothingSigmasPerLevel(sigmas);
    registration->SetMetricSamplingStrategy(Registration::MetricSamplingStrategyEnum::RANDOM);
    registration->SetMetricSamplingPercentage(0.2);
    registration->MetricSamplingReinitializeSeed(static_cast<int>(o.seed));
    registration->Update();
    PlainBaselineResult r;
    r.field = field_of(*transform, fixed.GetPointer());
    const auto versor = transform->GetVersor();
    r.figures.emplace_back("rotation_deg", 2.0 * std::acos(std::min(1.0, std::abs(versor.GetW()))) * 180.0 / M_PI);
    r.figures.emplace_back("translation_mm", transform->GetTranslation().GetNorm());
    r.figures.emplace_back("final_metric", optimizer->GetValue());
    r.figures.emplace_back("iterations_last_level", static_cast<double>(optimizer->GetCurrentIteration()));
    return r;
}

PlainBaselineResult demons(const Image::Pointer& fixed, Image::Pointer moving, bool labels_mode, const PlainBaselineOptions& o)
{
    if (!labels_mode) {
        auto matcher = itk::HistogramMatchingImageFilter<Image, Image>::New();
        matcher->SetInput(moving);
        matcher->SetReferenceImage(fixed);
        matcher->SetNumberOfHistogramLevels(1024);
        matcher->SetNumberOfMatchPoints(7);
        matcher->ThresholdAtMeanIntensityOn();
        matcher->Update();
        moving = matcher->GetOutput();
    }
    using Demons = itk::DiffeomorphicDemonsRegistrationFilter<Image, Image, Field>;
    using MultiResolution = itk::MultiResolutionPDEDeformableRegistration<Image, Image, Field, float>;
    auto filter = Demons::New();
    filter->SetStandardDeviations(o.demons_sigma_voxels);
    filter->SmoothDisplacementFieldOn();
    filter->SetMaximumUpdateStepLength(2.0);
    auto multi = MultiResolution::New();
    multi->SetRegistrationFilter(filter);
    multi->SetNumberOfLevels(static_cast<unsigned>(o.demons_iterations.size()));
    std::vector<unsigned> iterations(o.demons_iterations.begin(), o.demons_iterations.end());
    multi->SetNumberOfIterations(iterations.data());
    multi->SetFixedImage(fixed);
    multi->SetMovingImage(moving);
    multi->Update();
    const Field* out = multi->GetOutput();
    PlainBaselineResult r;
    const auto n = fixed->GetLargestPossibleRegion().GetNumberOfPixels();
    r.field.resize(3 * n);
    const auto* d = out->GetBufferPointer();
    for (std::size_t v = 0; v < n; ++v)
        for (unsigned a = 0; a < 3; ++a) r.field[3 * v + a] = d[v][a];
    r.figures.emplace_back("final_metric", filter->GetMetric());
    return r;
}

Image::Pointer smoothed(const Image::Pointer& image, double sigma_voxels)
{
    if (sigma_voxels <= 0.0) return image;
    auto smooth = itk::SmoothingRecursiveGaussianImageFilter<Image, Image>::New();
    smooth->SetInput(image);
    Image::SpacingType s = image->GetSpacing();
    itk::FixedArray<double, 3> sigma;
    for (unsigned a = 0; a < 3; ++a) sigma[a] = sigma_voxels * s[a];
    smooth->SetSigmaArray(sigma);
    smooth->Update();
    Image::Pointer out = smooth->GetOutput();
    out->DisconnectPipeline();
    return out;
}

using BSpline = itk::BSplineTransform<double, 3, 3>;

// Mean squares between the fixed samples and the warped moving image, with its gradient over the
// B-spline coefficients evaluated sparsely (the 64 coefficients whose support holds a sample). We
// write this cost ourselves (with ITK's transform, interpolator and optimiser) because ITK 5.2's
// metrics accumulate a dense derivative over every parameter per sample (a 4 000-parameter level took
// minutes) and its one sparse metric, Mattes mutual information, drifted by tens of mm on identical
// images (the B-spline free-form deformation overfits the Parzen histogram).
class BSplineMeanSquares final : public itk::SingleValuedCostFunction {
public:
    using Self = BSplineMeanSquares;
    using Pointer = itk::SmartPointer<Self>;
    itkNewMacro(Self);

    /// Samples lie at least `border` voxels inside the fixed image: there, smoothing the cropped fixed
    /// image and smoothing the whole moving one give the same values (no boundary effect).
    void setup(BSpline* transform, const Image::Pointer& fixed, const Image::Pointer& moving, double fraction, std::uint32_t seed, int border)
    {
        transform_ = transform;
        moving_ = moving;
        interpolator_ = itk::LinearInterpolateImageFunction<Image, double>::New();
        interpolator_->SetInputImage(moving);
        gradient_ = itk::CentralDifferenceImageFunction<Image, double>::New();
        gradient_->SetInputImage(moving);
        gradient_->SetUseImageDirection(true);
        // A fixed random subset of the fixed voxels (the same at every evaluation: a smooth cost).
        std::mt19937 random(seed);
        std::uniform_real_distribution<double> uniform(0.0, 1.0);
        points_.clear();
        values_.clear();
        itk::ImageRegionConstIteratorWithIndex<Image> it(fixed, fixed->GetLargestPossibleRegion());
        const auto size = fixed->GetLargestPossibleRegion().GetSize();
        for (; !it.IsAtEnd(); ++it) {
            if (uniform(random) > fraction) continue;
            bool interior = true;
            for (unsigned a = 0; a < 3; ++a)
                interior = interior && it.GetIndex()[a] >= border && it.GetIndex()[a] < static_cast<itk::IndexValueType>(size[a]) - border;
            if (!interior) continue;
            Image::PointType p;
            fixed->TransformIndexToPhysicalPoint(it.GetIndex(), p);
            points_.push_back(p);
            values_.push_back(it.Get());
        }
    }
    unsigned GetNumberOfParameters() const override { return transform_->GetNumberOfParameters(); }
    MeasureType GetValue(const ParametersType& p) const override
    {
        MeasureType value;
        DerivativeType d;
        GetValueAndDerivative(p, value, d);
        return value;
    }
    void GetDerivative(const ParametersType& p, DerivativeType& d) const override
    {
        MeasureType value;
        GetValueAndDerivative(p, value, d);
    }
    void GetValueAndDerivative(const ParametersType& p, MeasureType& value, DerivativeType& derivative) const override
    {
        transform_->SetParametersByValue(p);
        const unsigned n = transform_->GetNumberOfParameters();
        const unsigned per_dimension = transform_->GetNumberOfParametersPerDimension();
        derivative.SetSize(n);
        derivative.Fill(0.0);
        const auto count = static_cast<std::int64_t>(points_.size());
        // Partial sums over a fixed number of sample chunks, added in chunk order: the same bits
        // at every run and for every thread count.
        constexpr std::int64_t chunks = 16;
        std::vector<std::vector<double>> partial(static_cast<std::size_t>(chunks));
        std::vector<double> sums(static_cast<std::size_t>(chunks), 0.0);
        std::vector<std::int64_t> counts(static_cast<std::size_t>(chunks), 0);
#pragma omp parallel
        {
            BSpline::WeightsType weights(transform_->GetNumberOfWeights());
            BSpline::ParameterIndexArrayType indices(transform_->GetNumberOfWeights());
#pragma omp for schedule(dynamic, 1)
            for (std::int64_t c = 0; c < chunks; ++c) {
                const auto t = static_cast<std::size_t>(c);
                std::vector<double>& local = partial[t];
                local.assign(n, 0.0);
                for (std::int64_t s = c * count / chunks; s < (c + 1) * count / chunks; ++s) {
                    BSpline::OutputPointType y;
                    bool inside = false;
                    transform_->TransformPoint(points_[static_cast<std::size_t>(s)], y, weights, indices, inside);
                    if (!inside || !interpolator_->IsInsideBuffer(y)) continue;
                    const double r = interpolator_->Evaluate(y) - values_[static_cast<std::size_t>(s)];
                    const auto g = gradient_->Evaluate(y);
                    sums[t] += r * r;
                    ++counts[t];
                    for (unsigned k = 0; k < weights.Size(); ++k)
                        for (unsigned a = 0; a < 3; ++a) local[a * per_dimension + static_cast<unsigned>(indices[k])] += 2.0 * r * weights[k] * g[a];
                }
            }
        }
        double sum = 0.0;
        std::int64_t counted = 0;
        for (std::size_t t = 0; t < partial.size(); ++t) {
            sum += sums[t];
            counted += counts[t];
            for (unsigned i = 0; i < n && !partial[t].empty(); ++i) derivative[i] += partial[t][i];
        }
        if (counted == 0) fail("B-spline registration: no fixed sample maps into the moving image");
        value = sum / static_cast<double>(counted);
        derivative /= static_cast<double>(counted);
    }

private:
    BSpline* transform_ = nullptr;
    Image::Pointer moving_;
    itk::LinearInterpolateImageFunction<Image, double>::Pointer interpolator_;
    itk::CentralDifferenceImageFunction<Image, double>::Pointer gradient_;
    std::vector<Image::PointType> points_;
    std::vector<double> values_;
};

PlainBaselineResult bspline(const Image::Pointer& fixed, const Image::Pointer& moving, const PlainBaselineOptions& o)
{
    using Optimizer = itk::LBFGSBOptimizer;
    auto transform = BSpline::New();
    BSpline::MeshSizeType mesh;
    for (unsigned a = 0; a < 3; ++a) {
        const double extent = fixed->GetSpacing()[a] * static_cast<double>(fixed->GetLargestPossibleRegion().GetSize()[a]);
        mesh[a] = static_cast<unsigned>(std::max(1.0, std::round(extent / o.bspline_grid_mm)));
    }
    auto initializer = itk::BSplineTransformInitializer<BSpline, Image>::New();
    initializer->SetTransform(transform);
    initializer->SetImage(fixed);
    initializer->SetTransformDomainMeshSize(mesh);
    initializer->InitializeTransform();
    transform->SetIdentity();
    // Coarse to fine: control spacing halves and image smoothing (σ in voxels) shrinks per level.
    const double sigma[3] = {2, 1, 0};
    double metric_value = 0.0;
    int iterations = 0;
    for (int level = 0; level < 3; ++level) {
        if (level > 0) {
            BSpline::MeshSizeType finer;
            for (unsigned a = 0; a < 3; ++a) finer[a] = transform->GetTransformDomainMeshSize()[a] * 2;
            auto adaptor = itk::BSplineTransformParametersAdaptor<BSpline>::New();
            adaptor->SetTransform(transform);
            adaptor->SetRequiredTransformDomainMeshSize(finer);
            adaptor->SetRequiredTransformDomainOrigin(transform->GetTransformDomainOrigin());
            adaptor->SetRequiredTransformDomainDirection(transform->GetTransformDomainDirection());
            adaptor->SetRequiredTransformDomainPhysicalDimensions(transform->GetTransformDomainPhysicalDimensions());
            adaptor->AdaptTransformParameters();
        }
        const auto parameters = transform->GetNumberOfParameters();
        auto optimizer = Optimizer::New();
        Optimizer::BoundSelectionType selection(parameters);
        selection.Fill(0); // unbounded
        Optimizer::BoundValueType bound(parameters);
        bound.Fill(0.0);
        optimizer->SetBoundSelection(selection);
        optimizer->SetLowerBound(bound);
        optimizer->SetUpperBound(bound);
        optimizer->SetCostFunctionConvergenceFactor(1e7);
        optimizer->SetProjectedGradientTolerance(1e-8);
        optimizer->SetMaximumNumberOfIterations(static_cast<unsigned>(o.bspline_iterations));
        optimizer->SetMaximumNumberOfEvaluations(static_cast<unsigned>(3 * o.bspline_iterations));
        optimizer->SetMaximumNumberOfCorrections(7);
        auto cost = BSplineMeanSquares::New();
        cost->setup(transform.GetPointer(), smoothed(fixed, sigma[level]), smoothed(moving, sigma[level]), o.bspline_sampling, o.seed + static_cast<std::uint32_t>(level),
                    static_cast<int>(std::ceil(3.0 * sigma[level])));
        optimizer->SetCostFunction(cost);
        optimizer->SetInitialPosition(transform->GetParameters());
        optimizer->StartOptimization();
        transform->SetParametersByValue(optimizer->GetCurrentPosition());
        metric_value = optimizer->GetValue();
        iterations += static_cast<int>(optimizer->GetCurrentIteration());
    }
    PlainBaselineResult r;
    r.field = field_of(*transform, fixed.GetPointer());
    r.figures.emplace_back("final_mean_squares", metric_value);
    r.figures.emplace_back("iterations", iterations);
    r.figures.emplace_back("control_points", static_cast<double>(transform->GetNumberOfParameters() / 3));
    return r;
}

} // namespace

PlainBaselineResult itk_register_baseline(const PlainImage& fixed, const PlainImage& moving, const PlainBaselineOptions& o)
{
    itk::MultiThreaderBase::SetGlobalDefaultNumberOfThreads(static_cast<itk::ThreadIdType>(std::max(1, o.threads)));
    const Image::Pointer f = to_itk(fixed), m = to_itk(moving);
    try {
        if (o.method == "rigid") return rigid(f, m, o.labels_mode, o);
        if (o.method == "demons") return demons(f, m, o.labels_mode, o);
        if (o.method == "bspline") return bspline(f, m, o); // mean squares for both inputs
    } catch (const itk::ExceptionObject& e) {
        fail("{} registration ({}): ITK failed: {}", o.method, o.labels_mode ? "labels" : "intensity", e.GetDescription());
    }
    fail("baseline method '{}': use rigid, demons or bspline", o.method);
}

std::vector<float> itk_smooth(const PlainImage& image, double sigma_mm)
{
    auto smooth = itk::SmoothingRecursiveGaussianImageFilter<Image, Image>::New();
    smooth->SetInput(to_itk(image));
    smooth->SetSigma(sigma_mm);
    smooth->Update();
    const float* d = smooth->GetOutput()->GetBufferPointer();
    return std::vector<float>(d, d + image.values.size());
}

} // namespace physreg::detail
