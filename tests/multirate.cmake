# Issue 16: the multirate non-linear model (common/liver/multirate: a slow neo-Hookean tracker publishing a local
# contact model the 1 kHz loop evaluates).
surgsim_test(common_multirate_test SOURCES common/liver/multirate_test.cpp ${ALLOC} LIBS surgsim_liver surgsim_scene)
