// The side panel: base paints, the current colour, the force gauge and the status lines.

export const BASE_PAINTS = [
  ["titanium white", [0.96, 0.96, 0.94]], ["lemon yellow", [0.98, 0.86, 0.12]],
  ["cadmium orange", [0.95, 0.50, 0.10]], ["cadmium red", [0.80, 0.10, 0.10]],
  ["alizarin crimson", [0.55, 0.05, 0.20]], ["ultramarine", [0.14, 0.18, 0.62]],
  ["cerulean", [0.16, 0.52, 0.80]], ["viridian", [0.05, 0.50, 0.38]],
  ["burnt sienna", [0.54, 0.25, 0.10]], ["ivory black", [0.08, 0.08, 0.09]],
];

export function hex(rgb) {
  return "#" + rgb.map((c) => Math.round(Math.min(1, Math.max(0, c)) * 255).toString(16).padStart(2, "0")).join("");
}

export function fromHex(h) {
  return [1, 3, 5].map((i) => parseInt(h.slice(i, i + 2), 16) / 255);
}

export class Gauge {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.value = 0;
    this.peak = 0;
    this.scale = 1e-3;
    this.draw();
  }

  set(force) {
    const f = Math.hypot(force[0], force[1], force[2]);
    this.value = f;
    this.peak = Math.max(f, this.peak * 0.97);
    this.scale = Math.max(this.scale * 0.998, f * 1.25, 1e-3);
    this.draw();
  }

  draw() {
    const { ctx, canvas } = this;
    const w = canvas.width, h = canvas.height;
    ctx.clearRect(0, 0, w, h);
    const x0 = 10, x1 = w - 10, y = 24, bh = 14;
    ctx.fillStyle = "#1b1e23";
    ctx.beginPath(); ctx.roundRect(x0, y, x1 - x0, bh, 7); ctx.fill();
    const u = Math.min(1, this.value / this.scale);
    const grad = ctx.createLinearGradient(x0, 0, x1, 0);
    grad.addColorStop(0, "#5bbf7a"); grad.addColorStop(0.6, "#e0a34a"); grad.addColorStop(1, "#e0544a");
    ctx.fillStyle = grad;
    ctx.beginPath(); ctx.roundRect(x0, y, Math.max(bh, (x1 - x0) * u), bh, 7); ctx.fill();
    const p = x0 + (x1 - x0) * Math.min(1, this.peak / this.scale);
    ctx.fillStyle = "#e3e6eb"; ctx.fillRect(p - 1, y - 3, 2, bh + 6);
    ctx.fillStyle = "#8d96a5"; ctx.font = "11px system-ui, sans-serif";
    ctx.fillText("0", x0, y + bh + 14);
    ctx.textAlign = "right"; ctx.fillText(this.scale.toPrecision(2), x1, y + bh + 14);
    ctx.textAlign = "left"; ctx.fillStyle = "#e3e6eb"; ctx.font = "12px system-ui, sans-serif";
    ctx.fillText(`|F| = ${this.value.toPrecision(3)}`, x0, 16);
  }
}
