# Issue 16: corotational precomputed compliance and organ curves (common/liver/corotation, organ_curves; the haptic
# liver's corotational contacts; build/bench/large_deformation_bench).
surgsim_test(common_corotation_test SOURCES common/liver/corotation_test.cpp ${ALLOC} LIBS surgsim_liver surgsim_scene)
surgsim_test(common_organ_curves_test SOURCES common/liver/organ_curves_test.cpp LIBS surgsim_liver surgsim_scene)
surgsim_test(haptic_liver_corotation_test SOURCES haptic_node/organs/liver_corotation_test.cpp ${ALLOC} LIBS surgsim_haptic)
if(SURGSIM_BUILD_BENCHMARKS AND SURGSIM_BUILD_VISUAL)
  # Every method against the Newton reference at large deformation, the ticks and the visual frame (issue 16).
  surgsim_bench(large_deformation_bench SOURCES bench/large_deformation_bench.cpp
    LIBS surgsim_haptic surgsim_visual surgsim_mesher)
endif()
# scripts/report/large_deformation.py on a synthetic CSV (Debian's python3-matplotlib, as scripts_report_test).
add_test(NAME scripts_report_large_deformation_test
  COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/scripts/report_large_deformation_test.py ${SURGSIM_SOURCE_DIR})
