"""The Taylor machinery under `rkhp.systems` and `rkhp.integrators` (docs/engine.md).

- `rkhp.taylor.ops`: the opcode table (codes, kinds, the functions of mathematical text) and
  the scratch layout;
- `rkhp.taylor.tape`: recording programs as tapes (TapeBuilder, Var, composite operations and
  sub-programs);
- `rkhp.taylor.compiler`: numba's cache folder and compile settings, and numba for the compiled
  modules;
- `rkhp.taylor.numba_patches`: every patch rkhp makes to numba, applied once when the first
  compiled module takes numba;
- `rkhp.taylor.kernel_cache`: numba's cache kept working through damaged files, failed saves
  and unusable folders;
- `rkhp.taylor.jets`: jet spaces (monomial tables) and the jet kernels (product, composition);
- `rkhp.taylor.elementary`: the Taylor coefficients of every elementary function;
- `rkhp.taylor.rows`: evaluation of elementary rows (the main program's and sub-programs');
- `rkhp.taylor.linalg`: small dense LU factorisation and solve, the max-norm (no allocation);
- `rkhp.taylor.composites`: the kernels of composite operations;
- `rkhp.taylor.interpreter`: the tape interpreter (`run_tape`, work arrays, `evaluate`).

`ops`, `tape`, `compiler` and `kernel_cache` import neither numba nor anything compiled; the
other modules compile with numba (or patch it) and are imported only where something is
evaluated.
"""
