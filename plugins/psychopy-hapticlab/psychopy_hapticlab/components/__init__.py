"""Builder components: Haptic contact (:mod:`.contact`) and Haptic device check
(:mod:`.check`), and the hapticlab device backend of Builder's Device Manager
(:mod:`.backend`)."""
