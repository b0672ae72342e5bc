// SPDX-License-Identifier: GPL-3.0-or-later
// Every energy is a Form, and every Form passes the one finite-difference checker (issue 43 item 3).
// The cases are registered by the test files that build their fixtures (form_cases.hpp); this file
// runs them, checks the checker itself on forms with known derivatives, and fails when a class
// deriving from Form in include/physreg has no registered case.
#include "form_cases.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mechanics/forms/mechanics_forms.hpp"
#include "physreg/registration/images/segmentation_forms.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <regex>
#include <set>

namespace physreg {
namespace test {

std::vector<FormCase>& form_cases()
{
    static std::vector<FormCase> cases;
    return cases;
}

} // namespace test

namespace {

std::string gtest_name(const std::string& s)
{
    std::string out;
    for (char c : s) out += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
    return out;
}

std::vector<std::string> case_names()
{
    std::vector<std::string> names;
    for (const auto& c : test::form_cases()) names.push_back(c.form_class + ": " + c.name);
    return names;
}

class EveryForm : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryForm, PassesTheFiniteDifferenceCheck)
{
    const test::FormCase* found = nullptr;
    for (const auto& c : test::form_cases())
        if (c.form_class + ": " + c.name == GetParam()) found = &c;
    ASSERT_NE(found, nullptr);
    const test::FormCheckResult r = found->run();
    SCOPED_TRACE(r.check.summary());
    std::cout << r.check.summary() << "\n";
    EXPECT_GE(r.check.directions, r.min_directions) << "too few directions free of kinks";
    if (r.expect_gradient) {
        EXPECT_GT(r.check.gradient_norm, 0.0) << "a zero gradient checks nothing";
        EXPECT_LE(r.check.gradient_error, r.gradient_tolerance);
    }
    EXPECT_EQ(r.check.hessian_checked, r.expect_hessian);
    if (r.check.hessian_checked) {
        EXPECT_LE(r.check.hessian_error, r.hessian_tolerance);
    }
}

INSTANTIATE_TEST_SUITE_P(Forms, EveryForm, ::testing::ValuesIn(case_names()), [](const auto& info) { return gtest_name(info.param); });

// Every `class X : public Form` of the library's headers has at least one registered case.
TEST(Forms, EveryFormOfTheLibraryHasACase)
{
    const std::filesystem::path include = std::filesystem::path(PHYSREG_SOURCE_DIR) / "include" / "physreg";
    ASSERT_TRUE(std::filesystem::is_directory(include)) << include;
    const std::regex derived(R"(class\s+(\w+)\s*(?:final\s*)?:\s*public\s+(Form|AuxiliaryElements)\b)");
    std::set<std::string> classes, auxiliary, covered;
    for (const auto& entry : std::filesystem::recursive_directory_iterator(include)) {
        if (entry.path().extension() != ".hpp") continue;
        std::ifstream in(entry.path());
        const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        for (std::sregex_iterator m(text.begin(), text.end(), derived), end; m != end; ++m) {
            classes.insert((*m)[1]);
            if ((*m)[2] == "AuxiliaryElements") auxiliary.insert((*m)[1]);
        }
    }
    for (const auto& c : test::form_cases()) {
        covered.insert(c.form_class);
        // Auxiliary elements (membrane, beams) are checked through AuxiliaryElementsForm.
        if (auxiliary.count(c.form_class)) covered.insert("AuxiliaryElementsForm");
    }
    ASSERT_GE(classes.size(), 12u) << "the header scan found too few forms";
    for (const auto& c : classes) EXPECT_TRUE(covered.count(c)) << c << " derives from Form (or AuxiliaryElements) and has no finite-difference case";
}

// The checker itself: a quadratic with a known gradient passes; a wrong gradient and a wrong
// Hessian are caught, and a kink is skipped in piecewise-smooth mode.
class Quadratic : public Form {
public:
    explicit Quadratic(double gradient_error = 0.0, double hessian_error = 0.0, bool kink = false)
        : m_gradient_error(gradient_error), m_hessian_error(hessian_error), m_kink(kink)
    {
    }
    std::string name() const override { return "test quadratic"; }
    std::size_t size() const override { return 3; }
    double value(std::span<const double> x) const override
    {
        return 0.5 * (2 * x[0] * x[0] + 3 * x[1] * x[1] + x[2] * x[2]) + x[0] * x[1] + (m_kink ? std::abs(x[2]) : 0.0);
    }
    void gradient(std::span<const double> x, std::span<double> g) const override
    {
        g[0] = 2 * x[0] + x[1] + m_gradient_error;
        g[1] = 3 * x[1] + x[0];
        g[2] = x[2] + (m_kink ? (x[2] > 0 ? 1.0 : -1.0) : 0.0);
    }
    bool hessian_product(std::span<const double>, std::span<const double> v, std::span<double> p) const override
    {
        p[0] = 2 * v[0] + v[1];
        p[1] = v[0] + 3 * v[1] + m_hessian_error * v[1];
        p[2] = v[2];
        return true;
    }

private:
    double m_gradient_error, m_hessian_error;
    bool m_kink;
};

TEST(FiniteDifferenceCheck, PassesExactDerivativesAndCatchesWrongOnes)
{
    const std::vector<double> x{0.3, -0.2, 0.5};
    const auto exact = check_derivatives(Quadratic(), x);
    EXPECT_TRUE(exact.passed(1e-8, 1e-7)) << exact.summary();
    EXPECT_EQ(exact.directions, 3 + 4);
    EXPECT_FALSE(check_derivatives(Quadratic(1e-3), x).passed(1e-6, 1e-6));
    const auto bad_hessian = check_derivatives(Quadratic(0.0, 1e-2), x);
    EXPECT_LT(bad_hessian.gradient_error, 1e-8);
    EXPECT_GT(bad_hessian.hessian_error, 1e-3);
    // |x₂| has a kink at 0: a direction through it is skipped in piecewise-smooth mode.
    FiniteDifferenceOptions smooth;
    smooth.piecewise_smooth = true;
    smooth.random_directions = 0;
    const auto kinked = check_derivatives(Quadratic(0.0, 0.0, true), std::vector<double>{0.3, -0.2, 2e-7}, smooth); // within h of the kink
    EXPECT_EQ(kinked.skipped, 1);
    EXPECT_EQ(kinked.directions, 2);
    // Wrong sizes and steps are errors naming the form.
    EXPECT_THROW(check_derivatives(Quadratic(), std::vector<double>{1.0, 2.0}), Error);
    FiniteDifferenceOptions bad;
    bad.step = 0.0;
    EXPECT_THROW(check_derivatives(Quadratic(), x, bad), Error);
}

// Springs and the moduli prior have no fixture of their own elsewhere.
const test::RegisterFormCase springs{"SpringForm", "support springs on a third of 30 nodes", [] {
    std::vector<std::int32_t> nodes;
    for (std::int32_t n = 0; n < 30; n += 3) nodes.push_back(n);
    const SpringForm form(30, nodes, 0.7);
    std::vector<double> u(90);
    for (std::size_t i = 0; i < u.size(); ++i) u[i] = std::sin(0.37 * static_cast<double>(i));
    return test::FormCheckResult{check_derivatives(form, u), 1e-8, 1e-8};
}};

const test::RegisterFormCase prior{"ModuliPriorForm", "log-normal prior on two of three structures", [] {
    const ModuliPriorForm form(12.5, {std::log(3000.0), std::log(8000.0), std::log(2e4)}, {0, 2});
    const std::vector<double> y{std::log(4200.0), std::log(9000.0), std::log(1.1e4)};
    return test::FormCheckResult{check_derivatives(form, y), 1e-8, 1e-8};
}};

} // namespace
} // namespace physreg
