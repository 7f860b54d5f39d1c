"""The break-away probe's analysis (:mod:`.probe`) and its registry entry (:mod:`.entry`)."""
