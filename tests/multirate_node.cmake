# Issue 16: the multirate non-linear liver in the haptic node (haptic_node/organs/liver_multirate: the tracker on its
# own thread, the loop's partial match of its snapshots, the tracker's surface as BodyState; config/liver_multirate.yaml).
surgsim_test(haptic_liver_multirate_test SOURCES haptic_node/organs/liver_multirate_test.cpp ${ALLOC} LIBS surgsim_haptic)
