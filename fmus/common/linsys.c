/* Matrix exponential by scaling and squaring with a truncated Taylor series.
 *
 * The augmented matrix M = [[A, B], [0, 0]] h is scaled by 2^-s until its 1-norm is below 0.5,
 * where 16 Taylor terms are exact to machine precision, and the result is squared s times.
 * exp(M) = [[Phi, Gam], [0, I]] gives the exact discretisation for inputs held over the step.
 */
#include "linsys.h"

#include <math.h>
#include <string.h>

static void matmul(int k, const double *X, const double *Y, double *Z) {
    for (int i = 0; i < k; i++) {
        for (int j = 0; j < k; j++) {
            double s = 0.0;
            for (int l = 0; l < k; l++) s += X[i * k + l] * Y[l * k + j];
            Z[i * k + j] = s;
        }
    }
}

int linsys_zoh(int n, int m, const double *A, const double *B, double h, double *Phi, double *Gam) {
    const int k = n + m;
    if (k > LINSYS_MAX || n <= 0 || m < 0) return -1;
    double M[LINSYS_MAX * LINSYS_MAX] = {0};
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) M[i * k + j] = A[i * n + j] * h;
        for (int j = 0; j < m; j++) M[i * k + n + j] = B[i * m + j] * h;
    }
    double norm = 0.0;
    for (int j = 0; j < k; j++) {
        double col = 0.0;
        for (int i = 0; i < k; i++) col += fabs(M[i * k + j]);
        if (col > norm) norm = col;
    }
    int squarings = 0;
    if (norm > 0.5) squarings = (int)ceil(log2(norm / 0.5));
    if (squarings > 60) return -1;
    const double scale = ldexp(1.0, -squarings);
    for (int i = 0; i < k * k; i++) M[i] *= scale;

    double E[LINSYS_MAX * LINSYS_MAX] = {0};
    double term[LINSYS_MAX * LINSYS_MAX] = {0};
    double tmp[LINSYS_MAX * LINSYS_MAX];
    for (int i = 0; i < k; i++) E[i * k + i] = term[i * k + i] = 1.0;
    for (int p = 1; p <= 16; p++) {
        matmul(k, term, M, tmp);
        for (int i = 0; i < k * k; i++) {
            term[i] = tmp[i] / p;
            E[i] += term[i];
        }
    }
    for (int s = 0; s < squarings; s++) {
        matmul(k, E, E, tmp);
        memcpy(E, tmp, sizeof(double) * (size_t)(k * k));
    }
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) Phi[i * n + j] = E[i * k + j];
        for (int j = 0; j < m; j++) Gam[i * m + j] = E[i * k + n + j];
    }
    for (int i = 0; i < k * k; i++) {
        if (!isfinite(E[i])) return -1;
    }
    return 0;
}
