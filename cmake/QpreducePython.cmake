# Finds a Python 3 interpreter that can import NumPy and SciPy (the first on
# PATH may be a pyenv or venv interpreter without them), its development
# files, and pybind11 — all from Debian packages, nothing downloaded. Sets
# QPREDUCE_PYTHON_FOUND. A given -DPython3_EXECUTABLE=... is used as is.
set(QPREDUCE_PYTHON_FOUND OFF)
function(qpreduce_python_has_numpy result candidate)
  execute_process(COMMAND "${candidate}" -c "import numpy, scipy"
                  RESULT_VARIABLE rc OUTPUT_QUIET ERROR_QUIET)
  if(NOT rc EQUAL 0)
    set(${result} FALSE PARENT_SCOPE)
  endif()
endfunction()
if(NOT DEFINED Python3_EXECUTABLE)
  find_program(QPREDUCE_PYTHON3 NAMES python3 NAMES_PER_DIR VALIDATOR qpreduce_python_has_numpy)
  if(QPREDUCE_PYTHON3)
    set(Python3_EXECUTABLE "${QPREDUCE_PYTHON3}")
  endif()
  # Say so loudly when the first python3 on PATH is not the one: a user who
  # types `python3` gets an interpreter the package was not built for.
  find_program(QPREDUCE_FIRST_PYTHON3 NAMES python3 NAMES_PER_DIR NO_CACHE)
  if(QPREDUCE_FIRST_PYTHON3 AND NOT QPREDUCE_FIRST_PYTHON3 STREQUAL QPREDUCE_PYTHON3)
    if(QPREDUCE_PYTHON3)
      message(NOTICE "qpreduce: the Python package is built for ${QPREDUCE_PYTHON3}, not for the first python3 on "
                     "PATH (${QPREDUCE_FIRST_PYTHON3}), which cannot import numpy and scipy; run Python through "
                     "build/bin/qpreduce-python (that interpreter, the build's package on its path)")
    else()
      message(NOTICE "qpreduce: no python3 on PATH can import numpy and scipy (${QPREDUCE_FIRST_PYTHON3} cannot): "
                     "the Python package is not built; scripts/install-deps.sh installs python3-numpy and python3-scipy")
    endif()
  endif()
endif()
if(DEFINED Python3_EXECUTABLE)
  find_package(Python3 COMPONENTS Interpreter Development.Module)
  if(Python3_FOUND)
    find_package(pybind11 CONFIG)
    if(pybind11_FOUND)
      set(QPREDUCE_PYTHON_FOUND ON)
    endif()
  endif()
endif()
