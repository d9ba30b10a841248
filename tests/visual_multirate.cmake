# Issue 16: the visual node draws the multirate liver's shape (the haptic node's tracker, published as BodyState):
# views/liver_view with liver.deformation multirate, the shared BodyState listener, the real visual node over Fast DDS.
if(SURGSIM_BUILD_VISUAL)
  surgsim_test(visual_liver_view_test SOURCES visual_node/views/liver_view_test.cpp ${ALLOC} LIBS surgsim_visual)
endif()
