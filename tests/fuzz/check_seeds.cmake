# ctest fuzz_cache_seeds_are_current: runs MAKE (fuzz_make_seeds) into OUT and compares each file it made with the
# committed seed of the same name under CORPUS. A difference means the cache format changed: run
# `fuzz_make_seeds tests/fuzz/corpus` (build/fuzz/) and commit the new seeds.
file(REMOVE_RECURSE ${OUT})
execute_process(COMMAND ${MAKE} ${OUT} RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "fuzz_make_seeds failed (${status})")
endif()
file(GLOB_RECURSE made RELATIVE ${OUT} ${OUT}/*)
foreach(f ${made})
  execute_process(COMMAND ${CMAKE_COMMAND} -E compare_files ${OUT}/${f} ${CORPUS}/${f} RESULT_VARIABLE differ)
  if(NOT differ EQUAL 0)
    message(FATAL_ERROR "tests/fuzz/corpus/${f} is not what the cache code writes now: run "
                        "build/fuzz/fuzz_make_seeds tests/fuzz/corpus and commit the seeds")
  endif()
endforeach()
message(STATUS "cache seeds current: ${made}")
