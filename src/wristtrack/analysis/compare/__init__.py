"""Agreement with a reference system (`wristtrack compare`): reading the reference, time
alignment, spatial registration, agreement statistics."""
