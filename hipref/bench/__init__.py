"""Benchmarks: scripts that print figures, never tests that time (`make bench` runs the first five).

- `python -m hipref.bench.physics`: physics steps per second with each task's controller in the loop,
  against bare `mj_step` on the same model.
- `python -m hipref.bench.sweep`: one CPU-bound sweep with 1 and 2 local workers, and its speed-up.
- `python -m hipref.bench.teach`: the seconds a person waits for the next preference query after answering.
- `python -m hipref.bench.clips`: a noise sweep of SI runs with each environment's learning clips replayed
  against executed by every run.
- `python -m hipref.bench.startup`: a fresh interpreter's first wiping and pushing rollouts.
- `python -m hipref.bench.answers_time`: where notebook 12's time goes, per kind of run of its sweep.
- `python -m hipref.bench.model_choice`: what not knowing the teacher's model costs the Bayesian learner, in
  answers (no physics).

No row of the study depends on this package, so editing it keeps every cached cell (`hipref.sweep`).
"""
