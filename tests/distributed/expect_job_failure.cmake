# cmake -DMPIEXEC=<mpirun> -DDRIVER=<program> -DSTAGE=<stage> -DBOUND=<seconds> -P expect_job_failure.cmake
#
# Runs `<mpirun> --oversubscribe -np 2 <program> <stage>` and passes when the
# job ends by itself within BOUND seconds, with a non-zero exit, rank 1's
# "killing itself … at stage <stage>", mpirun's "rank 1 … exited on signal 9",
# and without rank 0's "unexpectedly finished" (kill_driver.cpp).
foreach(var MPIEXEC DRIVER STAGE BOUND)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "expect_job_failure.cmake: -D${var}=… is required")
  endif()
endforeach()
string(TIMESTAMP start "%s")
execute_process(COMMAND ${MPIEXEC} --oversubscribe -np 2 ${DRIVER} ${STAGE}
                TIMEOUT ${BOUND} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
string(TIMESTAMP stop "%s")
math(EXPR seconds "${stop} - ${start}")
message("${out}")
message("exit: ${rc}, after about ${seconds} s (bound ${BOUND} s)")
if(NOT rc MATCHES "^[0-9]+$")
  message(FATAL_ERROR "the job did not end by itself within ${BOUND} s: ${rc}")
endif()
if(rc EQUAL 0)
  message(FATAL_ERROR "the job exited 0 although rank 1 was killed")
endif()
if(NOT out MATCHES "rank 1: killing itself [^\n]* at stage ${STAGE}")
  message(FATAL_ERROR "rank 1 did not reach stage ${STAGE}")
endif()
if(NOT out MATCHES "rank 1 [^\n]*exited on signal 9")
  message(FATAL_ERROR "no message from mpirun naming the killed rank 1")
endif()
if(out MATCHES "unexpectedly finished")
  message(FATAL_ERROR "a rank finished the build without rank 1")
endif()
