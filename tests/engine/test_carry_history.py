"""The rebuild moves each contact's history in place to its key's new slot (kernels/neighbors.carry_history)."""

import numpy as np
import warp as wp

from warpdem.kernels.neighbors import carry_history
from warpdem.kernels.params import ContactHistory


@wp.kernel
def _carry(
    old_keys: wp.array2d[int],
    old_count: wp.array[int],
    new_keys: wp.array2d[int],
    new_count: wp.array[int],
    history: wp.array2d[ContactHistory],
    live: wp.array[wp.uint64],
):
    i = wp.tid()
    live[i] = carry_history(old_keys, old_count[i], new_keys, new_count[i], history, i, live[i])


def test_every_new_key_gets_its_old_history_or_zero():
    """400 random columns of 16 slots: keys kept, dropped and added, so entries move both up and down and some
    overwrite slots that others still have to read. Each history holds its own key, so a wrong move shows; each
    new slot's live bit is its old slot's."""
    rng = np.random.default_rng(7)
    cols, cap = 400, 16
    old_keys = np.full((cap, cols), -7, np.int32)
    new_keys = np.full((cap, cols), -7, np.int32)
    old_n = rng.integers(0, cap + 1, cols)
    new_n = rng.integers(0, cap + 1, cols)
    history = np.zeros((cap, cols), dtype=ContactHistory.numpy_dtype())
    for c in range(cols):
        pool = rng.choice(40, size=cap + 8, replace=False)
        old = np.sort(rng.choice(pool, size=old_n[c], replace=False))
        new = np.sort(rng.choice(pool, size=new_n[c], replace=False))
        old_keys[: old_n[c], c] = old
        new_keys[: new_n[c], c] = new
        for s, k in enumerate(old):
            history[s, c]["spring"] = (k, 2 * k, 3 * k)
            history[s, c]["aux"] = k + 1
    hist = wp.array(history, dtype=ContactHistory)
    live_old = rng.integers(0, 2**63, cols, dtype=np.uint64)
    live = wp.array(live_old, dtype=wp.uint64)
    wp.launch(
        _carry,
        dim=cols,
        inputs=[
            wp.array(old_keys),
            wp.array(old_n.astype(np.int32)),
            wp.array(new_keys),
            wp.array(new_n.astype(np.int32)),
        ],
        outputs=[hist, live],
    )
    out, live_new = hist.numpy(), live.numpy()
    moved_up = moved_down = 0
    for c in range(cols):
        old = list(old_keys[: old_n[c], c])
        for s, k in enumerate(new_keys[: new_n[c], c]):
            if k in old:
                moved_up += old.index(k) < s
                moved_down += old.index(k) > s
                assert out[s, c]["aux"] == k + 1 and tuple(out[s, c]["spring"]) == (k, 2 * k, 3 * k), (c, s, k)
                assert (live_new[c] >> np.uint64(s)) & 1 == (live_old[c] >> np.uint64(old.index(k))) & 1
            else:
                assert out[s, c]["aux"] == 0 and not np.any(out[s, c]["spring"]), (c, s, k)
                assert (live_new[c] >> np.uint64(s)) & 1 == 0
    assert moved_up > 100 and moved_down > 100, "the cases should move histories both ways"
    assert np.all(live_new >> np.uint64(cap) == 0), "no bit past the new lists"
