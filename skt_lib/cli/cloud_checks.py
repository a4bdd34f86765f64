"""Does a cloud look like what the model was trained on — a partial view of a hook, in the
support frame (metres, wall plane x = 0, x out of the wall, z up)? ``skt predict`` refuses
what cannot be a hook and warns where the frame looks wrong; a robot would execute either.

Thresholds are set from the training views (``data/render_views``, 120 supports × 42 views
of the embedded default) with a wide margin; the figures are in the comments:

- **No structure off the wall** (refused): fewer than :data:`MIN_OFF_WALL_SHARE` of the
  points lie more than :data:`OFF_WALL_M` in front of the wall plane. Training views: at least
  2.5 % (median 33 %). A cloud of a bare wall, or of the plate alone, has none.
- **Far from the origin** (warning): the centroid lies more than :data:`FAR_M` from the
  support frame's origin. Training views: at most 0.07 m. A cloud left in a camera frame
  is typically metres away.
- **Behind the wall** (warning): more than :data:`BEHIND_SHARE` of the points lie more than
  :data:`BEHIND_M` behind x = 0. Training views: none (the 2 % quantile of x is ≥ 0). A cloud
  whose up or out-of-wall axis is turned (z forward, as a camera's optical axis) puts the
  plate's half behind it.

Each warning says what to do: ``--camera`` for a raw camera cloud with the wall in view (the
frame is found from the wall), ``--frame`` for a cloud whose camera pose is known.

Not caught: a cloud turned about x alone (upside down, or z and y swapped) keeps the wall
plane where it is; nothing in a partial view of an arbitrary hook says reliably which way
is up. The confidence figures in the JSON (the classifier's probability, the affordance
peak) are the controller's second line there.
"""

import numpy as np

from skt_lib.errors import InputError

OFF_WALL_M = 0.02
MIN_OFF_WALL_SHARE = 0.01
FAR_M = 0.25
BEHIND_M = 0.005
BEHIND_SHARE = 0.05
#: what each warning advises
ADVICE = ("a raw depth-camera cloud with the wall in view? pass --camera (with --up X Y Z or "
          "--level) to find the support frame from the wall; a cloud whose camera pose you "
          "know: pass --frame T.json")


def check_support_cloud(points: np.ndarray, name: str = "points") -> list[str]:
    """Warnings (one line each) for a cleaned cloud ``(N, 3)`` in the support frame, metres;
    raises :class:`InputError` when no structure stands off the wall."""
    pts = np.asarray(points, float)
    centroid = pts.mean(0)
    dist = float(np.linalg.norm(centroid))
    warnings = []
    if dist > FAR_M:
        warnings.append(
            f"{name}: its centroid is {dist:.2f} m from the support frame's origin (training "
            f"clouds: within 0.07 m) — is it still in the camera frame? " + ADVICE)
    behind = float(np.mean(pts[:, 0] < -BEHIND_M))
    if behind > BEHIND_SHARE:
        warnings.append(
            f"{name}: {100 * behind:.0f} % of its points lie behind the wall plane x = 0 — "
            "its axes may not be the support frame's (x out of the wall, z up): " + ADVICE)
    off = float(np.mean(pts[:, 0] > OFF_WALL_M))
    if off < MIN_OFF_WALL_SHARE and dist <= FAR_M:
        raise InputError(
            f"{name}: no structure stands off the wall ({100 * off:.1f} % of points more than "
            f"{100 * OFF_WALL_M:.0f} cm in front of x = 0; a hook's view has ≥ 2.5 %) — "
            "is there a hook in this cloud, and is it in the support frame? " + ADVICE)
    return warnings
