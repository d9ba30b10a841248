# Issue 15, the intestine's self-collision detection (topic "detect").
# The scene's intestine.detector key.
surgsim_test(common_scene_detector_test SOURCES common/scene/scene_detector_test.cpp LIBS surgsim_scene)
