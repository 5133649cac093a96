"""The smoke tipper's first-contact speed against the bucket's turn time (issue 23): how much of the full-size
first contacts' excess over free fall from the lip is the speed grains leave the turning bucket with.

    python docs/seeds/002/tipper_dump.py     (CPU, about 35 s; output in tipper_dump.txt)

One line per dump_duration: the lip's free-fall speed sqrt(2 g lip), the largest normal impact speed on the body
in the first contacts (0.1 s from the output tick that first sees one) and in the whole loading."""

import json
import math

from warpdem.scene import rigs
from warpdem.scene.runner import run_scene

for dump in (1.5, 3.0, 6.0):
    values = {**rigs.SMOKE["truck_tipper"], "dump_duration": dump}
    p = rigs.params("truck_tipper", values)
    m = run_scene(rigs.spec("truck_tipper", {"dump_duration": dump}, smoke=True), frames=False, quiet=True).metrics[0]
    first, loading = m["phases"]["first_contacts"]["Body"], m["phases"]["loading"]["Body"]
    row = {
        "dump_duration_s": dump,
        "lip_m": p.lip_height,
        "free_fall_m_s": round(math.sqrt(2 * 9.81 * p.lip_height), 3),
        "first_contacts_max_m_s": round(first["max_speed_m_s"], 3),
        "first_contacts_count": first["total_count"],
        "loading_max_m_s": round(loading["max_speed_m_s"], 3),
        "first_contacts_s": m["first_contacts_s"],
    }
    print(json.dumps(row), flush=True)
