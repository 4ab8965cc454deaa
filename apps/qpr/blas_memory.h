// qpr — the linear algebra's work buffers, reserved while there is room.
//
// OpenBLAS takes a work buffer of about 128 MiB per thread on its first
// level-3 call and, when the allocation fails, retries for ever (a process
// under `ulimit -v` then spins at 100 % CPU inside CHOLMOD's factorization
// instead of failing). Under an address-space limit, reserve_blas_buffers
// checks up front that the buffers fit, and takes them at once (one small
// product) so that a later shortage is an ordinary, reported allocation
// failure. Under such a limit qpr runs OpenBLAS on one thread: its worker
// threads take their buffers when the library loads, and would retry them
// for ever (and the exit wait for them).
#pragma once

namespace qpr {

// Under an address-space limit and without OPENBLAS_NUM_THREADS in the
// environment: sets OPENBLAS_NUM_THREADS=1 and starts this program again
// with the same arguments (execv of /proc/self/exe; returns only when that
// fails: true after a message on stderr). Otherwise returns false at once.
bool single_threaded_blas_under_limit(char** argv);

// No-op without an address-space limit (RLIMIT_AS) or without OpenBLAS.
// Otherwise throws std::runtime_error ("out of memory: the address-space
// limit (ulimit -v) …", naming the limit, what is free, what the buffers
// need and how to run) when they do not fit, else takes them.
void reserve_blas_buffers();

}  // namespace qpr
