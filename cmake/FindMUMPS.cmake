# FindMUMPS
# ---------
# Finds the double-precision parallel MUMPS (Debian: libmumps-dev, and
# libmumps-ptscotch-dev for the PT-Scotch parallel ordering) and defines the
# imported target MUMPS::MUMPS. Debian's MUMPS ships no CMake config, so this
# module looks for dmumps_c.h and the libraries dmumps, mumps_common and pord.
#
# The PT-Scotch build (libdmumps_ptscotch) is preferred: it is the one of
# Debian's builds with a parallel ordering (ICNTL(28) = 2, ICNTL(29) = 1);
# the plain build orders on the host (AMD, AMF, QAMD, PORD).
#
# Result variables: MUMPS_FOUND, MUMPS_INCLUDE_DIR, MUMPS_LIBRARIES,
# MUMPS_HAS_PTSCOTCH (ON for the PT-Scotch build).
# The caller finds MPI (find_package(MPI COMPONENTS CXX)) and links MPI::MPI_CXX.
find_path(MUMPS_INCLUDE_DIR dmumps_c.h PATH_SUFFIXES mumps)
find_library(MUMPS_DMUMPS_PTSCOTCH_LIBRARY dmumps_ptscotch)
find_library(MUMPS_COMMON_PTSCOTCH_LIBRARY mumps_common_ptscotch)
find_library(MUMPS_PORD_PTSCOTCH_LIBRARY pord_ptscotch)
find_library(MUMPS_DMUMPS_LIBRARY dmumps)
find_library(MUMPS_COMMON_LIBRARY mumps_common)
find_library(MUMPS_PORD_LIBRARY pord)

set(MUMPS_HAS_PTSCOTCH OFF)
if(MUMPS_DMUMPS_PTSCOTCH_LIBRARY AND MUMPS_COMMON_PTSCOTCH_LIBRARY)
  set(MUMPS_HAS_PTSCOTCH ON)
  set(MUMPS_LIBRARY ${MUMPS_DMUMPS_PTSCOTCH_LIBRARY})
  set(MUMPS_LIBRARIES ${MUMPS_DMUMPS_PTSCOTCH_LIBRARY} ${MUMPS_COMMON_PTSCOTCH_LIBRARY})
  if(MUMPS_PORD_PTSCOTCH_LIBRARY)
    list(APPEND MUMPS_LIBRARIES ${MUMPS_PORD_PTSCOTCH_LIBRARY})
  endif()
elseif(MUMPS_DMUMPS_LIBRARY AND MUMPS_COMMON_LIBRARY)
  set(MUMPS_LIBRARY ${MUMPS_DMUMPS_LIBRARY})
  set(MUMPS_LIBRARIES ${MUMPS_DMUMPS_LIBRARY} ${MUMPS_COMMON_LIBRARY})
  if(MUMPS_PORD_LIBRARY)
    list(APPEND MUMPS_LIBRARIES ${MUMPS_PORD_LIBRARY})
  endif()
endif()

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(MUMPS REQUIRED_VARS MUMPS_LIBRARY MUMPS_INCLUDE_DIR)

if(MUMPS_FOUND AND NOT TARGET MUMPS::MUMPS)
  add_library(MUMPS::MUMPS INTERFACE IMPORTED)
  set_target_properties(MUMPS::MUMPS PROPERTIES
    INTERFACE_INCLUDE_DIRECTORIES "${MUMPS_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${MUMPS_LIBRARIES}")
endif()
mark_as_advanced(MUMPS_INCLUDE_DIR MUMPS_DMUMPS_PTSCOTCH_LIBRARY MUMPS_COMMON_PTSCOTCH_LIBRARY
                 MUMPS_PORD_PTSCOTCH_LIBRARY MUMPS_DMUMPS_LIBRARY MUMPS_COMMON_LIBRARY MUMPS_PORD_LIBRARY)
