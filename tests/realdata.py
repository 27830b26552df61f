"""The shared real frames the tests and benchmarks use, and what we know of them.

``../shared/data`` beside the repository (never copied into it): the paper
authors' first-person frames with their DHG images (``egonet-samples``) and
three consecutive 640x480 RGB-D frames of a room (``rgbd-primesense``,
16-bit depth in millimetres, with intrinsics). Tests that use them skip
when the folder is absent.
"""

from pathlib import Path

import cv2
import numpy as np

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
PRIMESENSE = SHARED_DATA / "rgbd-primesense"
EGONET_SAMPLES = SHARED_DATA / "egonet-samples"

#: A box (x0, y0), (x1, y1) around the chair of rgbd-primesense 00001.
CHAIR_BOX = [(335, 105), (610, 390)]
#: (x, y) on the chair's white backrest, 20 cm before the white wall.
BACKREST = (420, 150)


def chair_truth() -> np.ndarray:
    """The chair of rgbd-primesense 00001, drawn by hand from the image: bool (480, 640).

    Backrest with the left armrest's band and leg, the seat, the right
    armrest's loop, the left foot. The wall seen through the right loop and
    under the seat is not the chair. The camera barely moves over the three
    frames, so it fits 00000 and 00002 too.
    """
    m = np.zeros((480, 640), np.uint8)
    back_left = [(350, 110), (483, 112), (484, 198), (495, 210), (495, 242), (402, 242), (402, 357), (398, 372),
                 (386, 380), (382, 340), (382, 288), (365, 262), (354, 225), (340, 208), (340, 198), (350, 190)]
    seat = [(402, 242), (600, 244), (606, 256), (604, 270), (585, 282), (540, 292), (480, 297), (402, 297)]
    cv2.fillPoly(m, [np.array(back_left, np.int32), np.array(seat, np.int32)], 1)
    arm = [(487, 203), (505, 195), (535, 196), (565, 208), (585, 225), (597, 245), (592, 285), (597, 320),
           (590, 350), (570, 366), (540, 370), (510, 362), (485, 345)]
    cv2.polylines(m, [np.array(arm, np.int32)], False, 1, 12)
    cv2.polylines(m, [np.array([(342, 350), (360, 366), (378, 378)], np.int32)], False, 1, 9)
    return m.astype(bool)
