/* Exact zero-order-hold discretisation of a small linear system x' = A x + B u. */
#ifndef TWIN_LINSYS_H
#define TWIN_LINSYS_H

#define LINSYS_MAX 8 /* n + m */

/* Fill Phi (n x n) = exp(A h) and Gam (n x m) = integral_0^h exp(A s) ds B, row-major.
 * Returns 0, or -1 if n + m exceeds LINSYS_MAX or the result is not finite. */
int linsys_zoh(int n, int m, const double *A, const double *B, double h, double *Phi, double *Gam);

#endif
