// qpreduce — handing the heap's free memory back to the system.
#pragma once

namespace qpreduce {

// glibc's malloc_trim (a no-op elsewhere). glibc keeps freed blocks that lie
// below live ones, so the temporaries of one phase of a large precompute
// (assembly, symbolic analysis) would otherwise stay resident under the next
// phase's peak.
void release_free_heap();

}  // namespace qpreduce
