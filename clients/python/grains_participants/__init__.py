"""Example grains participants in Python, written from protocol/README.md.

- `grains_participants.wire`: the messages, the checksum and the scene hash (§3, §4);
- `grains_participants.scene`: what a time owner reads from the scene file (§6.1);
- `grains_participants.participant`: joining a run, its services, liveness (§1, §5, §7);
- `grains_participants.coupler`: an external coupler (§3.4–§3.8, §6), runnable as
  `python -m grains_participants.coupler --scene S --run-id R`;
- `grains_participants.mpm`: an external MPM (a small elastic MPM in numpy) for coupled runs,
  runnable as `python -m grains_participants.mpm --scene S --run-id R`.
"""
