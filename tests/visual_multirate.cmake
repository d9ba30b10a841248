# Issue 16: the visual node draws the multirate liver's shape (the haptic node's tracker, published as BodyState):
# views/liver_view with liver.deformation multirate, the shared BodyState listener, the real visual node over Fast DDS.
if(SURGSIM_BUILD_VISUAL)
  surgsim_test(visual_liver_view_test SOURCES visual_node/views/liver_view_test.cpp ${ALLOC} LIBS surgsim_visual)
  # The real visual node over Fast DDS: this test's BodyStates (drawn, or ignored by reason), then both real nodes on
  # config/liver_multirate.yaml (the drawn VTK is the haptic node's last published shape).
  surgsim_test(integration_visual_multirate_test SOURCES integration/visual_multirate_test.cpp
    LIBS surgsim_visual nlohmann_json::nlohmann_json)
  add_dependencies(integration_visual_multirate_test visual_node haptic_node)
endif()
if(SURGSIM_BUILD_BENCHMARKS AND SURGSIM_BUILD_VISUAL)
  # The visual node's cost of the multirate shape against the linear deformer; the BodyState's bytes on the wire.
  surgsim_bench(multirate_view_bench SOURCES bench/multirate_view_bench.cpp LIBS surgsim_visual)
endif()
