# Issue 17 (patient-size organs): the liver's tensors stored as they are read, at a proportional size (a generated
# ~3000-node liver; the 21k-node figures come from build/bench/liver_bench and build/bench/node_bench). The unit
# tests of the layout, the threaded solve and the cache version sit in common_liver_test.
surgsim_test(common_liver_scale_test SOURCES common/liver/scale_test.cpp LIBS surgsim_liver surgsim_scene surgsim_mesher)
