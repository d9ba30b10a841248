# Issue 15, the intestine's speed and live missed deadlines (topic "intestine_speed").
# CPU placement and the CPU wake-up latency request (common/os).
surgsim_test(common_os_placement_test SOURCES common/os/cpu_affinity_test.cpp common/os/cpu_latency_test.cpp
  LIBS surgsim_os)
# The haptic node's --cpu (loop alone on its CPU, every other thread off it) and --tick-trace, on a paced run.
surgsim_test(haptic_placement_test SOURCES haptic_node/haptic_placement_test.cpp LIBS surgsim_haptic)
# SURGSIM_HAPTIC_CPU=N scripts/run_local.sh: the loop pinned, also beside --cpu-latency-us in HAPTIC_ARGS.
if(SURGSIM_BUILD_VISUAL)
  add_test(NAME run_local_placement_test
    COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/integration/run_local_placement_test.sh ${SURGSIM_SOURCE_DIR} ${CMAKE_BINARY_DIR}
            ${CMAKE_BINARY_DIR}/run_local_placement_test)
  set_tests_properties(run_local_placement_test PROPERTIES TIMEOUT 120 SKIP_RETURN_CODE 77)
endif()
