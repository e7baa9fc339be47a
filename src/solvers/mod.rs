//! Solvers: hierarchical refinement plus gathering (Jacobi, Gauss–Seidel) with push-pull.
