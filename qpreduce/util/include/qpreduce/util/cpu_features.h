// qpreduce — which vector kernels this process may use, its own and the
// system BLAS's.
//
// The project is compiled for baseline x86-64; its AVX2 + FMA kernels (the
// engine's frame products and point reconstruction, the deform plugin's
// rotation lanes) are chosen at run time through cpu_has_avx2_fma(), so that
// one environment variable turns all of them off together.
//
// The engine's large dense products (the precompute's, the on-site step's)
// go to the system BLAS (OpenBLAS on Debian), which picks its kernels for the
// CPU when it is loaded. Debian 12's OpenBLAS (0.3.21) does not know Intel
// CPUs newer than itself (for example family 6, model 207) and runs its
// generic Prescott (SSE3) kernels there (what that costs the precompute and
// the on-site step: docs/performance.md, "The BLAS kernels"). OpenBLAS reads
// its choice from the environment only when it is loaded, so the
// command-line programs call restart_with_blas_core() first thing in main(),
// and Python's package calls prefer_blas_core() before NumPy loads OpenBLAS.
#pragma once

#include <string>

namespace qpreduce {

// True when the CPU has AVX2 and FMA and the environment variable
// QPREDUCE_DISABLE_AVX2 is unset or "0" (set it to compare the kernels
// against their portable versions in the same build). Read once per process;
// false on every CPU that is not x86-64.
bool cpu_has_avx2_fma();

// The OpenBLAS kernel family that suits this CPU, as OPENBLAS_CORETYPE names
// it: "SkylakeX" on an Intel CPU with AVX-512 F, CD, BW, DQ and VL, "Haswell"
// on an Intel CPU with AVX2 and FMA, "" otherwise (other vendors and older
// CPUs keep OpenBLAS's own detection). Reads no environment variable.
const char* preferred_blas_core();

// Sets OPENBLAS_CORETYPE to preferred_blas_core() when that is not "", the
// variable is unset and QPREDUCE_KEEP_BLAS_CORE is unset (a value the user
// chose always wins). Has an effect only on an OpenBLAS loaded later (Python
// imports it after this). Returns whether it set the variable.
bool prefer_blas_core();

// The kernel family the loaded OpenBLAS runs (its openblas_get_corename():
// "Haswell", "SkylakeX", "Prescott", …), or "" when the process has no
// OpenBLAS.
std::string blas_core();

// For main(argc, argv) of a program: when the loaded OpenBLAS fell back to
// its generic "Prescott" kernels on a CPU for which preferred_blas_core()
// names a family, and prefer_blas_core() sets the variable, replaces the
// process by the same program with the same arguments (execv of
// /proc/self/exe), so that OpenBLAS loads again with the kernels for this CPU.
// Returns (without restarting) in every other case: no OpenBLAS, its choice
// already fits, the variable set by the user or by an earlier restart,
// QPREDUCE_KEEP_BLAS_CORE set, a run under valgrind (whose tools would not
// follow the new process), or execv failing. Call it before any thread,
// file or MPI initialisation.
void restart_with_blas_core(char** argv);

}  // namespace qpreduce
