# Issue 16, organ curves over the whole organ: the haptic tick applies the organ law's surface field at its own contact
# nodes (common/liver/organ_curves, nonlinear_law; haptic_node/organs/liver_contacts.cpp).
surgsim_test(haptic_liver_contacts_organ_law_test SOURCES haptic_node/organs/liver_contacts_organ_law_test.cpp ${ALLOC}
  LIBS surgsim_haptic)
