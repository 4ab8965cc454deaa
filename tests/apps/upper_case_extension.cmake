# qpr deform with upper-case extensions: a tet mesh read as .MESH and written
# as .MESH, a surface read as .OFF and written as .OBJ, as the plugin's own
# readers dispatch (case-insensitive).
#   cmake -DQPR=<qpr> -DBS=<botsch-sorkine dir> -DTETS=<tets dir> -DOUT=<dir> -P upper_case_extension.cmake
file(MAKE_DIRECTORY ${OUT})
configure_file(${TETS}/octopus-low.mesh ${OUT}/OCTOPUS.MESH COPYONLY)
configure_file(${BS}/bar.off ${OUT}/BAR.OFF COPYONLY)

# The octopus: its first 40 nodes fixed, its last 40 a handle moved by 0.05 in x.
set(_sel "# per vertex status: 0=fixed, 1=deformable-region, 2=handle\n")
foreach(_v RANGE 0 451)
  if(_v LESS 40)
    string(APPEND _sel "0\n")
  elseif(_v GREATER 411)
    string(APPEND _sel "2\n")
  else()
    string(APPEND _sel "1\n")
  endif()
endforeach()
file(WRITE ${OUT}/octopus.sel "${_sel}")
file(WRITE ${OUT}/octopus.def "1 0 0 0.05\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")

function(run_qpr expected_output)
  file(REMOVE ${expected_output})
  execute_process(COMMAND ${QPR} deform ${ARGN} RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
  if(NOT _rc EQUAL 0)
    message(FATAL_ERROR "qpr deform ${ARGN} exited with ${_rc}:\n${_out}\n${_err}")
  endif()
  if(NOT EXISTS ${expected_output})
    message(FATAL_ERROR "qpr deform ${ARGN} did not write ${expected_output}")
  endif()
endfunction()

run_qpr(${OUT}/OCTOPUS_OUT.MESH ${OUT}/OCTOPUS.MESH --sel ${OUT}/octopus.sel --def ${OUT}/octopus.def
        --linear-proxies 12 --rotational-proxies 8 --out ${OUT}/OCTOPUS_OUT.MESH)
file(READ ${OUT}/OCTOPUS_OUT.MESH _head LIMIT 200)
if(NOT _head MATCHES "MeshVersionFormatted")
  message(FATAL_ERROR "${OUT}/OCTOPUS_OUT.MESH is not a MEDIT tet mesh")
endif()
run_qpr(${OUT}/BAR_OUT.OBJ ${OUT}/BAR.OFF --sel ${BS}/bar.sel --def ${BS}/bar.def
        --linear-proxies 12 --rotational-proxies 12 --out ${OUT}/BAR_OUT.OBJ)
