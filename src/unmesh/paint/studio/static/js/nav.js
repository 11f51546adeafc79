// Orbit navigation: the page owns the view (yaw, pitch, zoom, pan) and sends it whole.
// Right drag rotates, middle drag or shift+right drag pans, the wheel zooms; arrows, +/-,
// Home/0 and the preset buttons from the keyboard and the view bar.

export class Navigator {
  constructor(onChange) {
    this.onChange = onChange;   // (view, preview) => void
    this.view = { yaw: 60, pitch: 20, zoom: 1, pan: [0, 0] };
    this.drag = null;
  }

  set(view, preview = false) {
    const v = { ...this.view, ...view };
    v.pitch = Math.max(-89.5, Math.min(89.5, v.pitch));
    v.yaw = ((v.yaw + 180) % 360 + 360) % 360 - 180;
    v.zoom = Math.max(0.1, Math.min(40, v.zoom));
    v.pan = [Math.max(-50, Math.min(50, v.pan[0])), Math.max(-50, Math.min(50, v.pan[1]))];
    this.view = v;
    this.onChange(v, preview);
  }

  preset(name, presets) {
    const p = presets?.[name];
    if (p) this.set({ yaw: p[0], pitch: p[1], zoom: 1, pan: [0, 0] });
  }

  start(ev, mode) { this.drag = { mode, x: ev.clientX, y: ev.clientY, view: { ...this.view } }; }

  move(ev, height) {
    if (!this.drag) return;
    const dx = ev.clientX - this.drag.x, dy = ev.clientY - this.drag.y;
    const v = this.drag.view;
    if (this.drag.mode === "rotate") {
      this.set({ yaw: v.yaw - dx * 0.4, pitch: v.pitch + dy * 0.4 }, true);
    } else {
      const k = 2.2 / (height * v.zoom);
      this.set({ pan: [v.pan[0] - dx * k, v.pan[1] + dy * k] }, true);
    }
  }

  end() {
    if (!this.drag) return false;
    this.drag = null;
    this.set({}, false);
    return true;
  }

  wheel(ev) { this.set({ zoom: this.view.zoom * Math.exp(-ev.deltaY * 0.0015) }); }

  key(ev, presets) {
    const step = ev.shiftKey ? 45 : 10;
    const v = this.view;
    switch (ev.key) {
      case "ArrowLeft": this.set({ yaw: v.yaw - step }); return true;
      case "ArrowRight": this.set({ yaw: v.yaw + step }); return true;
      case "ArrowUp": this.set({ pitch: v.pitch + step }); return true;
      case "ArrowDown": this.set({ pitch: v.pitch - step }); return true;
      case "+": case "=": this.set({ zoom: v.zoom * 1.2 }); return true;
      case "-": case "_": this.set({ zoom: v.zoom / 1.2 }); return true;
      case "Home": case "0": this.preset("home", presets); return true;
      default: return false;
    }
  }
}
