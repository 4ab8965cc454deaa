// Handing freed heap back; see heap.h.
#include "qpreduce/util/heap.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

namespace qpreduce {

void release_free_heap() {
#ifdef __GLIBC__
  malloc_trim(0);
#endif
}

}  // namespace qpreduce
