# FindCHOLMOD
# -----------
# Finds CHOLMOD from SuiteSparse (Debian: libsuitesparse-dev) and defines the
# imported target CHOLMOD::CHOLMOD. SuiteSparse 5.x ships no CMake config, so
# this module looks for the header and the libraries CHOLMOD links against.
find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse)
find_library(CHOLMOD_LIBRARY cholmod)
find_library(CHOLMOD_AMD_LIBRARY amd)
find_library(CHOLMOD_CAMD_LIBRARY camd)
find_library(CHOLMOD_COLAMD_LIBRARY colamd)
find_library(CHOLMOD_CCOLAMD_LIBRARY ccolamd)
find_library(CHOLMOD_CONFIG_LIBRARY suitesparseconfig)
find_package(BLAS QUIET)
find_package(LAPACK QUIET)

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(CHOLMOD
  REQUIRED_VARS CHOLMOD_LIBRARY CHOLMOD_INCLUDE_DIR CHOLMOD_AMD_LIBRARY
                CHOLMOD_COLAMD_LIBRARY CHOLMOD_CONFIG_LIBRARY)

if(CHOLMOD_FOUND AND NOT TARGET CHOLMOD::CHOLMOD)
  add_library(CHOLMOD::CHOLMOD UNKNOWN IMPORTED)
  set(_cholmod_deps ${CHOLMOD_AMD_LIBRARY} ${CHOLMOD_COLAMD_LIBRARY} ${CHOLMOD_CONFIG_LIBRARY})
  foreach(_lib CHOLMOD_CAMD_LIBRARY CHOLMOD_CCOLAMD_LIBRARY)
    if(${_lib})
      list(APPEND _cholmod_deps ${${_lib}})
    endif()
  endforeach()
  if(LAPACK_FOUND)
    list(APPEND _cholmod_deps ${LAPACK_LIBRARIES})
  endif()
  if(BLAS_FOUND)
    list(APPEND _cholmod_deps ${BLAS_LIBRARIES})
  endif()
  set_target_properties(CHOLMOD::CHOLMOD PROPERTIES
    IMPORTED_LOCATION "${CHOLMOD_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${CHOLMOD_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${_cholmod_deps}")
endif()
mark_as_advanced(CHOLMOD_INCLUDE_DIR CHOLMOD_LIBRARY CHOLMOD_AMD_LIBRARY CHOLMOD_CAMD_LIBRARY
                 CHOLMOD_COLAMD_LIBRARY CHOLMOD_CCOLAMD_LIBRARY CHOLMOD_CONFIG_LIBRARY)
