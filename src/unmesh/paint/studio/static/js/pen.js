// Pen, mouse and touch input to evenly spaced brush samples.
// Pressure: the pen's, except for a mouse and for hardware without pressure, which reports
// exactly 0.5 (or 0): then the pressure slider (the wheel moves it while painting).
// Tilt: [about the view's x axis, about its y axis] in degrees = Pointer Events [tiltY, tiltX];
// from altitudeAngle/azimuthAngle when tiltX/tiltY are missing.

export function pressureOf(ev, fallback) {
  if (ev.pointerType === "mouse" || ev.pressure === 0.5 || !(ev.pressure > 0)) return fallback;
  return Math.min(1, Math.max(0, ev.pressure));
}

export function tiltOf(ev) {
  if (ev.pointerType !== "pen") return [0, 0];
  let tx = ev.tiltX, ty = ev.tiltY;
  if ((tx === undefined || ty === undefined) && ev.altitudeAngle !== undefined) {
    const alt = ev.altitudeAngle, az = ev.azimuthAngle || 0;
    const t = Math.tan(alt);
    tx = t === 0 ? 90 : Math.atan(Math.cos(az) / t) * 180 / Math.PI;
    ty = t === 0 ? 90 : Math.atan(Math.sin(az) / t) * 180 / Math.PI;
  }
  return [ty || 0, tx || 0];
}

// Resamples a polyline of input points {t, x, y, p, ax, ay} at a fixed distance along it, so a
// stroke's samples do not depend on how fast the pointer moved (dab spacing by distance).
export class Resampler {
  constructor(spacing) {
    this.spacing = Math.max(0.5, spacing);
    this.prev = null;     // last input point
    this.carry = 0;       // distance since the last emitted sample
  }

  push(pt) {
    const out = [];
    if (this.prev === null) {
      out.push(row(pt));
      this.prev = pt;
      this.carry = 0;
      return out;
    }
    const a = this.prev;
    const seg = Math.hypot(pt.x - a.x, pt.y - a.y);
    if (seg === 0) { this.prev = { ...pt }; return out; }
    let d = this.spacing - this.carry;
    while (d <= seg) {
      const u = d / seg;
      out.push(row(lerp(a, pt, u)));
      d += this.spacing;
    }
    this.carry = seg - (d - this.spacing);
    this.prev = pt;
    return out;
  }
}

function lerp(a, b, u) {
  return { t: a.t + u * (b.t - a.t), x: a.x + u * (b.x - a.x), y: a.y + u * (b.y - a.y),
           p: a.p + u * (b.p - a.p), ax: a.ax + u * (b.ax - a.ax), ay: a.ay + u * (b.ay - a.ay) };
}

function row(s) {
  const r = (v, k) => Math.round(v * k) / k;
  return [r(s.t, 100), r(s.x, 100), r(s.y, 100), r(s.p, 1000), r(s.ax, 100), r(s.ay, 100)];
}

// The input points of one pointer event: every coalesced event (the full input rate).
export function inputPoints(ev, toImage, fallbackPressure) {
  const list = (typeof ev.getCoalescedEvents === "function" && ev.getCoalescedEvents().length)
    ? ev.getCoalescedEvents() : [ev];
  return list.map((e) => {
    const [x, y] = toImage(e);
    const [ax, ay] = tiltOf(e);
    return { t: e.timeStamp, x, y, p: pressureOf(e, fallbackPressure), ax, ay };
  });
}
