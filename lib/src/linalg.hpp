// beaconloc — small dense symmetric linear algebra on fixed-size matrices
// without Eigen's dynamic-size kernels: Eigen's SelfAdjointEigenSolver and
// LLT run their blocks through GEMV, whose stack-or-heap temporary
// references malloc (check-lib-clink's `nm -u`; lib/README.md), so the team
// solver and the team filter use these instead. Private to the library.
#ifndef BEACONLOC_LINALG_HPP
#define BEACONLOC_LINALG_HPP

#include <Eigen/Jacobi>

#include "internal.hpp"

namespace bl {

// Eigen-decomposition of a symmetric A by the cyclic Jacobi method (Golub &
// Van Loan, "Matrix Computations", 4th ed., Alg. 8.5.3), each rotation by
// Eigen's JacobiRotation::makeJacobi (the 2x2 symmetric Schur
// decomposition, G&VL Alg. 8.5.1): A = V diag(λ) Vᵀ. On return A holds
// diag(λ) (up to the off-diagonal rounding), V (may be NULL) the
// eigenvectors as columns. False when 50 sweeps leave the off-diagonal
// norm above 4ε of the whole (quadratic convergence: ~6-10 sweeps).
template <int N> bool symmetric_eigen(Mat<N, N> &A, Mat<N, N> *V)
{
    if (V) V->setIdentity();
    const real eps = real(4) * Eigen::NumTraits<real>::epsilon();
    for (int sweep = 0; sweep < 50; ++sweep) {
        real off = 0, all = 0;
        for (int r = 0; r < N; ++r)
            for (int c = 0; c < N; ++c) {
                all += A(r, c) * A(r, c);
                if (r != c) off += A(r, c) * A(r, c);
            }
        if (!(off <= eps * eps * all)) {
            if (!is_finite(off)) return false;
        } else {
            return true;
        }
        for (int p = 0; p < N - 1; ++p)
            for (int q = p + 1; q < N; ++q) {
                if (A(p, q) == real(0)) continue;
                Eigen::JacobiRotation<real> J;
                if (!J.makeJacobi(A, p, q)) continue;  // already diagonal in (p, q)
                A.applyOnTheLeft(p, q, J.adjoint());
                A.applyOnTheRight(p, q, J);
                if (V) V->applyOnTheRight(p, q, J);
            }
    }
    return false;
}

// Cholesky factor L (lower) of a symmetric positive-definite A = L Lᵀ
// (Cholesky–Banachiewicz, G&VL Alg. 4.2.1); false when a pivot is not
// positive or not finite. *ratio: (min Lᵢᵢ / max Lᵢᵢ)², a cheap lower
// estimate of the reciprocal condition (small for a nearly singular A).
template <int N> bool cholesky(const Mat<N, N> &A, Mat<N, N> *L, real *ratio)
{
    L->setZero();
    real lmin = 0, lmax = 0;
    for (int j = 0; j < N; ++j) {
        real s = A(j, j);
        for (int k = 0; k < j; ++k) s -= (*L)(j, k) * (*L)(j, k);
        if (!(s > real(0)) || !is_finite(s)) return false;
        const real d = std::sqrt(s);
        (*L)(j, j) = d;
        lmin = j == 0 ? d : std::fmin(lmin, d);
        lmax = std::fmax(lmax, d);
        for (int i = j + 1; i < N; ++i) {
            real t = A(i, j);
            for (int k = 0; k < j; ++k) t -= (*L)(i, k) * (*L)(j, k);
            (*L)(i, j) = t / d;
        }
    }
    if (ratio) *ratio = (lmin / lmax) * (lmin / lmax);
    return true;
}

// x = A⁻¹ b from A's Cholesky factor: L y = b, Lᵀ x = y.
template <int N> Mat<N, 1> cholesky_solve(const Mat<N, N> &L, const Mat<N, 1> &b)
{
    Mat<N, 1> y;
    for (int i = 0; i < N; ++i) {
        real t = b(i);
        for (int k = 0; k < i; ++k) t -= L(i, k) * y(k);
        y(i) = t / L(i, i);
    }
    Mat<N, 1> x;
    for (int i = N - 1; i >= 0; --i) {
        real t = y(i);
        for (int k = i + 1; k < N; ++k) t -= L(k, i) * x(k);
        x(i) = t / L(i, i);
    }
    return x;
}

}  // namespace bl

#endif
