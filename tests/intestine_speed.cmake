# Issue 15, the intestine's speed and live missed deadlines (topic "intestine_speed").
# CPU placement and the CPU wake-up latency request (common/os).
surgsim_test(common_os_placement_test SOURCES common/os/cpu_affinity_test.cpp common/os/cpu_latency_test.cpp
  LIBS surgsim_os)
# The haptic node's --cpu (loop alone on its CPU, every other thread off it) and --tick-trace, on a paced run.
surgsim_test(haptic_placement_test SOURCES haptic_node/haptic_placement_test.cpp LIBS surgsim_haptic)
