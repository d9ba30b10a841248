# Issue 15, the intestine's self-collision detection (topic "detect").
# The scene's intestine.detector key.
surgsim_test(common_scene_detector_test SOURCES common/scene/scene_detector_test.cpp LIBS surgsim_scene)
# Issue 15: a probe folds the mesentery onto the intestine; only the membrane (point/edge-triangle) cases see it.
surgsim_test(common_intestine_membrane_fold_test SOURCES common/intestine/membrane_fold_test.cpp
  LIBS surgsim_intestine)
