"""The operator's inputs to the loop: the enabling device and the "mark point" button.

**Enabling device.** Hand guiding moves the robot only while the operator holds a three-position
enabling device (ISO 10218-1 5.8.3 / IEC 60204-1 10.9, and ISO/TS 15066's hand guiding, which
starts motion only on the operator's deliberate action). :class:`EnablingDevice` turns the
device's level into the controller's deadman input by the *fresh press* rule:

* guiding starts only on a press (released → pressed) seen while the loop is ready (the
  estimator has warmed up and tared, no fault latched, no stop requested);
* the device is taken as held until it is first seen released, so a device held when the
  session starts, or when the loop becomes ready, counts only after a release and a new press;
* a release, a fault or anything that makes the loop not ready drops the engagement, and the
  next start needs a fresh press again.

The loop's readiness gates the press, not the level: the estimator's warm-up (its status not
OK) is never taken for a release that arms the next press.

**Mark button.** :class:`MarkButton` turns the button's level into one mark per press: a
rising edge after the button was released for at least ``debounce_s`` (a contact bounces for a
few milliseconds; a button held at the start marks nothing until it is released).

Both keep named state and allocate nothing per call.
"""

from __future__ import annotations

import math

__all__ = ["EnablingDevice", "MarkButton", "input_bit"]

#: Times closer than this are equal (sample times are sums of periods, rounded) [s].
_TIME_TOLERANCE_S = 1e-9


def input_bit(inputs: int, bit: int) -> bool:
    """Whether input ``bit`` (0-based) of the bit field ``inputs`` is set."""
    return bool((inputs >> bit) & 1)


class EnablingDevice:
    """The fresh-press rule of the enabling device (see the module doc).

    Attributes:
        was_held: The level of the last update (True before the first: unknown counts as held).
        engaged: A fresh press was accepted and the device is still held (the deadman input).
    """

    __slots__ = ("engaged", "was_held")

    def __init__(self) -> None:
        self.was_held = True
        self.engaged = False

    def reset(self) -> None:
        """Forget the device's history: the next start needs a release and a press."""
        self.was_held = True
        self.engaged = False

    def update(self, held: bool, ready: bool) -> bool:
        """One controller cycle: the device's level and the loop's readiness in, the deadman
        input out.

        Args:
            held: The device is pressed (its middle position).
            ready: The loop can start guiding now (estimator OK, no fault, no stop requested).

        Returns:
            Whether guiding is enabled: a fresh press was seen while ready and the device has
            been held since, with the loop ready throughout.
        """
        fresh = held and not self.was_held
        self.was_held = held
        if not (held and ready):
            self.engaged = False
        elif fresh:
            self.engaged = True
        return self.engaged

    @property
    def needs_release(self) -> bool:
        """Held but not engaged: the operator must release the device and press it again."""
        return self.was_held and not self.engaged


class MarkButton:
    """One mark per press of the "mark point" button (see the module doc).

    Args:
        debounce_s: The button must have been released this long before a press counts [s].

    Attributes:
        pressed: The level of the last update (True before the first).
        released_at: Time the button was last seen released after a press [s] (NaN: not yet).
    """

    __slots__ = ("debounce_s", "pressed", "released_at")

    def __init__(self, debounce_s: float = 0.02) -> None:
        self.debounce_s = debounce_s
        self.pressed = True
        self.released_at = math.nan

    def update(self, pressed: bool, t: float) -> bool:
        """The button's level at time ``t`` [s]; returns True on a press that counts as a mark.
        """
        was = self.pressed
        self.pressed = pressed
        if not pressed:
            if was:
                self.released_at = t
            return False
        return not was and t - self.released_at >= self.debounce_s - _TIME_TOLERANCE_S
