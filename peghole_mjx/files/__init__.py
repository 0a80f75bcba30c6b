"""Files on disk: durable writes (:mod:`.fileio`), the one-writer lock (:mod:`.lock`), the
provenance stamped on every result (:mod:`.provenance`) and a training run's checkpoint
folders (:mod:`.checkpoint_folders`)."""
