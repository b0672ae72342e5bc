// SPDX-License-Identifier: GPL-3.0-or-later
#include "mechanics/detail/amg_pcg.hpp"

#include "mechanics/detail/timing.hpp"
#include "physreg/core/error.hpp"

// The C API of MPI only (OpenMPI's deprecated C++ bindings would need libmpi_cxx).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <HYPRE.h>
#include <HYPRE_parcsr_ls.h>
#include <mpi.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <mutex>

// Exported by libHYPRE but declared only in its internal header _hypre_parcsr_ls.h.
extern "C" {
HYPRE_Int HYPRE_BoomerAMGSetSmoothInterpVectors(HYPRE_Solver solver, HYPRE_Int smooth_interp_vectors);
HYPRE_Int HYPRE_BoomerAMGSetInterpRefine(HYPRE_Solver solver, HYPRE_Int num_refine);
}

namespace physreg::detail {
namespace {


// hypre needs MPI (Debian's build links OpenMPI) even on one process. A program that did not start
// MPI itself (mpirun with physreg enrich does) gets a singleton MPI here, finalised at exit.
void ensure_runtime()
{
    static std::once_flag once;
    std::call_once(once, [] {
        int initialised = 0;
        MPI_Initialized(&initialised);
        if (!initialised) {
            int provided = 0;
            MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
            std::atexit([] {
                int finalised = 0;
                MPI_Finalized(&finalised);
                if (!finalised) MPI_Finalize();
            });
        }
        HYPRE_Init();
    });
}

// Owns a hypre IJ vector.
struct Vector {
    HYPRE_IJVector ij = nullptr;
    HYPRE_ParVector par = nullptr;
    Vector(HYPRE_BigInt n, const double* values)
    {
        HYPRE_IJVectorCreate(MPI_COMM_SELF, 0, n - 1, &ij);
        HYPRE_IJVectorSetObjectType(ij, HYPRE_PARCSR);
        HYPRE_IJVectorInitialize(ij);
        std::vector<HYPRE_BigInt> rows(static_cast<std::size_t>(n));
        for (HYPRE_BigInt i = 0; i < n; ++i) rows[static_cast<std::size_t>(i)] = i;
        HYPRE_IJVectorSetValues(ij, static_cast<HYPRE_Int>(n), rows.data(), values);
        HYPRE_IJVectorAssemble(ij);
        HYPRE_IJVectorGetObject(ij, reinterpret_cast<void**>(&par));
    }
    ~Vector() { HYPRE_IJVectorDestroy(ij); }
    Vector(const Vector&) = delete;
    Vector& operator=(const Vector&) = delete;
};

} // namespace

AmgPcgResult solve_amg_pcg(const SparseMatrix& k, const Eigen::VectorXd& b, Eigen::VectorXd& x, const std::vector<double>& coordinates,
                           double tolerance, int max_iterations)
{
    ensure_runtime();
    AmgPcgResult result;
    const auto setup_start = std::chrono::steady_clock::now();
    const auto n = static_cast<HYPRE_BigInt>(k.rows());
    if (n % 3 != 0) fail("pcg-amg: {} unknowns is not 3 per node", n);
    if (!coordinates.empty() && coordinates.size() != static_cast<std::size_t>(n))
        fail("pcg-amg: {} coordinates for {} unknowns", coordinates.size(), n);

    // The symmetric CSC matrix read column by column is its CSR.
    HYPRE_IJMatrix ij_matrix;
    HYPRE_IJMatrixCreate(MPI_COMM_SELF, 0, n - 1, 0, n - 1, &ij_matrix);
    HYPRE_IJMatrixSetObjectType(ij_matrix, HYPRE_PARCSR);
    std::vector<HYPRE_Int> sizes(static_cast<std::size_t>(n));
    std::vector<HYPRE_BigInt> rows(static_cast<std::size_t>(n)), columns(static_cast<std::size_t>(k.nonZeros()));
    for (HYPRE_BigInt c = 0; c < n; ++c) {
        sizes[static_cast<std::size_t>(c)] = k.outerIndexPtr()[c + 1] - k.outerIndexPtr()[c];
        rows[static_cast<std::size_t>(c)] = c;
    }
    for (Eigen::Index p = 0; p < k.nonZeros(); ++p) columns[static_cast<std::size_t>(p)] = k.innerIndexPtr()[p];
    HYPRE_IJMatrixSetRowSizes(ij_matrix, sizes.data());
    HYPRE_IJMatrixInitialize(ij_matrix);
    HYPRE_IJMatrixSetValues(ij_matrix, static_cast<HYPRE_Int>(n), sizes.data(), rows.data(), columns.data(), k.valuePtr());
    HYPRE_IJMatrixAssemble(ij_matrix);
    HYPRE_ParCSRMatrix matrix;
    HYPRE_IJMatrixGetObject(ij_matrix, reinterpret_cast<void**>(&matrix));

    x.setZero(b.size());
    Vector rhs(n, b.data()), solution(n, x.data());
    // Rotations about the three axes (the translations are implicit in the systems approach).
    std::vector<std::unique_ptr<Vector>> modes;
    std::vector<HYPRE_ParVector> mode_pointers;
    if (!coordinates.empty()) {
        const std::size_t nodes = static_cast<std::size_t>(n) / 3;
        for (int axis = 0; axis < 3; ++axis) {
            const int a = (axis + 1) % 3, c = (axis + 2) % 3; // rotation in the (a, c) plane
            std::vector<double> mode(static_cast<std::size_t>(n), 0.0);
            for (std::size_t i = 0; i < nodes; ++i) {
                mode[3 * i + a] = coordinates[3 * i + c];
                mode[3 * i + c] = -coordinates[3 * i + a];
            }
            modes.push_back(std::make_unique<Vector>(n, mode.data()));
            mode_pointers.push_back(modes.back()->par);
        }
    }

    // BoomerAMG for systems: nodal coarsening on the row-sum norm of the 3×3 blocks, as one V-cycle
    // per CG step; with coordinates, also hypre's GM-2 interpolation of the rigid rotations.
    HYPRE_Solver amg;
    HYPRE_BoomerAMGCreate(&amg);
    HYPRE_BoomerAMGSetNumFunctions(amg, 3);
    HYPRE_BoomerAMGSetAggNumLevels(amg, 0);
    HYPRE_BoomerAMGSetStrongThreshold(amg, 0.5);
    HYPRE_BoomerAMGSetNodal(amg, 4);
    HYPRE_BoomerAMGSetNodalDiag(amg, 1);
    HYPRE_BoomerAMGSetCycleRelaxType(amg, 8, 3);
    if (!mode_pointers.empty()) {
        HYPRE_BoomerAMGSetInterpVecVariant(amg, 2);
        HYPRE_BoomerAMGSetInterpVecQMax(amg, 4);
        HYPRE_BoomerAMGSetSmoothInterpVectors(amg, 1);
        HYPRE_BoomerAMGSetInterpRefine(amg, 1);
        HYPRE_BoomerAMGSetInterpVectors(amg, static_cast<HYPRE_Int>(mode_pointers.size()), mode_pointers.data());
    }
    HYPRE_BoomerAMGSetMaxIter(amg, 1);
    HYPRE_BoomerAMGSetTol(amg, 0.0);
    HYPRE_BoomerAMGSetPrintLevel(amg, 0);

    HYPRE_Solver pcg;
    HYPRE_ParCSRPCGCreate(MPI_COMM_SELF, &pcg);
    HYPRE_PCGSetMaxIter(pcg, max_iterations);
    HYPRE_PCGSetTol(pcg, tolerance);
    HYPRE_PCGSetTwoNorm(pcg, 1);
    HYPRE_PCGSetPrintLevel(pcg, 0);
    HYPRE_PCGSetLogging(pcg, 1);
    HYPRE_PCGSetPrecond(pcg, reinterpret_cast<HYPRE_PtrToSolverFcn>(HYPRE_BoomerAMGSolve),
                        reinterpret_cast<HYPRE_PtrToSolverFcn>(HYPRE_BoomerAMGSetup), amg);
    HYPRE_ParCSRPCGSetup(pcg, matrix, rhs.par, solution.par);
    result.setup_s = seconds_since(setup_start);
    const auto solve_start = std::chrono::steady_clock::now();
    HYPRE_ParCSRPCGSolve(pcg, matrix, rhs.par, solution.par);
    HYPRE_ClearAllErrors(); // non-convergence is read from the residual below
    HYPRE_Int iterations = 0;
    HYPRE_Real residual = 0.0;
    HYPRE_PCGGetNumIterations(pcg, &iterations);
    HYPRE_PCGGetFinalRelativeResidualNorm(pcg, &residual);
    result.iterations = iterations;
    result.relative_residual = residual;
    result.converged = residual <= tolerance && std::isfinite(residual);
    std::vector<HYPRE_BigInt> all(static_cast<std::size_t>(n));
    for (HYPRE_BigInt i = 0; i < n; ++i) all[static_cast<std::size_t>(i)] = i;
    HYPRE_IJVectorGetValues(solution.ij, static_cast<HYPRE_Int>(n), all.data(), x.data());
    result.solve_s = seconds_since(solve_start);

    HYPRE_ParCSRPCGDestroy(pcg);
    HYPRE_BoomerAMGDestroy(amg);
    HYPRE_IJMatrixDestroy(ij_matrix);
    return result;
}

} // namespace physreg::detail
