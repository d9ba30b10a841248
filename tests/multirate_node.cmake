# Issue 16: the multirate non-linear liver in the haptic node (haptic_node/organs/liver_multirate: the tracker on its
# own thread, the loop's partial match of its snapshots, the tracker's surface as BodyState; config/liver_multirate.yaml).
surgsim_test(haptic_liver_multirate_test SOURCES haptic_node/organs/liver_multirate_test.cpp ${ALLOC} LIBS surgsim_haptic)
# The real haptic node on config/liver_multirate.yaml with its grasp-and-lift trajectory, against the same scene linear.
surgsim_test(integration_haptic_multirate_test SOURCES integration/haptic_multirate_test.cpp
  LIBS nlohmann_json::nlohmann_json Eigen3::Eigen)
add_dependencies(integration_haptic_multirate_test haptic_node)
if(SURGSIM_BUILD_BENCHMARKS)
  # The node's multirate force along the scene's grasp-and-lift in real time against Newton on the same targets.
  surgsim_bench(multirate_node_bench SOURCES bench/multirate_node_bench.cpp LIBS surgsim_haptic)
endif()
