"""The physics benchmark's flight on its jump prompts with an interval: the median per-segment flight fit (pelvis
parabola, m/s^2) over the 4 jump prompts (jumping jacks left out), 95 % bootstrap over their motions (prompt x seed),
per KeyMotion run of ``salad eval --physics --keymotion DIR --no-salad --out RUN``.

    python lab/scripts/keymotion/keymotion_flight_bootstrap.py RUN/physics.json [RUN2/physics.json ...]
"""
import json, sys
import numpy as np
JUMPS = ('a person jumps', 'a man is jumping high', 'a person hops in place', 'a man jumps forward')
WALKS = ('a person walks forward', 'a man walks slowly', 'a person runs forward', 'a woman jogs forward', 'a man marches forward')
rng = np.random.default_rng(0)
for path in sys.argv[1:]:
    p = json.load(open(path))['generators']['KeyMotion']['prompts']
    motions = [r.get('flight_segment_accels') or [] for x in p if x['text'] in JUMPS for r in x['reports']]
    found = sum(1 for m in motions if m)
    med = np.median([a for m in motions for a in m])
    boots = []
    for _ in range(2000):
        idx = rng.integers(0, len(motions), len(motions))
        segs = [a for i in idx for a in motions[i]]
        boots.append(np.median(segs))
    lo, hi = np.percentile(boots, [2.5, 97.5])
    print(f"{path}: flight fit median {med:.2f} [{lo:.2f}, {hi:.2f}] over {sum(len(m) for m in motions)} segments; flight found in {found}/{len(motions)} jump samples")
