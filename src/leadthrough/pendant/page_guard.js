// The pendant's page guard: a held button (the hold-to-run enabling device) lets go when the
// page loses the operator's attention. On window blur, on the page becoming hidden and on
// pagehide, every button still held by a pointer gets a bubbling pointercancel (and loses its
// pointer capture), so that the page's own handler stops the button's heartbeat; the pendant
// then releases the enabling device within its lease (200 ms). Self-contained, no globals
// but one flag against a second copy.
(function () {
  "use strict";
  if (window.__leadthroughPageGuard) return;
  window.__leadthroughPageGuard = true;
  var held = new Map(); // pointerId -> [the button it went down on, the element hit]
  document.addEventListener("pointerdown", function (e) {
    var button = e.target instanceof Element ? e.target.closest("button") : null;
    if (button) held.set(e.pointerId, [button, e.target]);
  }, true);
  function up(e) { held.delete(e.pointerId); }
  document.addEventListener("pointerup", up, true);
  document.addEventListener("pointercancel", up, true);
  function letGo() {
    var pending = Array.from(held.entries());
    held.clear();
    pending.forEach(function (entry) {
      var id = entry[0], button = entry[1][0];
      [button, entry[1][1]].forEach(function (el) {
        try {
          if (el.hasPointerCapture(id)) el.releasePointerCapture(id);
        } catch (err) { /* the pointer is gone already */ }
      });
      button.dispatchEvent(new PointerEvent("pointercancel", {
        bubbles: true, cancelable: false, pointerId: id, isPrimary: true,
      }));
    });
  }
  window.addEventListener("blur", letGo);
  window.addEventListener("pagehide", letGo);
  document.addEventListener("visibilitychange", function () {
    if (document.visibilityState === "hidden") letGo();
  });
})();
