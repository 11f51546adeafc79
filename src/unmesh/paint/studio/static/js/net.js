// The WebSocket session: JSON messages out, JSON replies and binary frames in.
// Frame format (see unmesh/paint/studio/frames.py): uint32 LE header length, JSON header,
// then one image per rectangle [x, y, w, h, nbytes]: a JPEG (head.fmt "jpeg", returned as a
// Blob) or raw RGBA rows (head.fmt "rgba", returned as ImageData, drawn without decoding).

export function decodeFrame(buffer) {
  const view = new DataView(buffer);
  const n = view.getUint32(0, true);
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
  let pos = 4 + n;
  const blobs = head.rects.map((r) => {
    const blob = head.fmt === "rgba"
      ? new ImageData(new Uint8ClampedArray(buffer, pos, r[4]), r[2], r[3])
      : new Blob([new Uint8Array(buffer, pos, r[4])], { type: "image/jpeg" });
    pos += r[4];
    return blob;
  });
  return { head, blobs };
}

export class Connection {
  constructor(token, handlers) {
    this.token = token;
    this.handlers = handlers;   // {onFrame(head, blobs, receivedAt), onMessage(msg), onOpen(), onClose()}
    this.ws = null;
    this.retry = 250;
    this.connect();
  }

  connect() {
    const url = `ws://${location.host}/ws?token=${encodeURIComponent(this.token)}`;
    const ws = new WebSocket(url);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => { this.retry = 250; this.handlers.onOpen?.(); };
    ws.onmessage = (ev) => {
      if (typeof ev.data === "string") {
        let msg;
        try { msg = JSON.parse(ev.data); } catch { return; }
        this.handlers.onMessage?.(msg);
      } else {
        const recv = performance.now();
        const { head, blobs } = decodeFrame(ev.data);
        this.handlers.onFrame?.(head, blobs, recv);
      }
    };
    ws.onclose = (ev) => {
      this.handlers.onClose?.(ev);
      if (ev.code === 1008 || ev.code === 4403) return;
      setTimeout(() => this.connect(), this.retry);
      this.retry = Math.min(this.retry * 2, 4000);
    };
    this.ws = ws;
  }

  get open() { return this.ws && this.ws.readyState === WebSocket.OPEN; }

  send(msg) {
    if (!this.open) return false;
    this.ws.send(JSON.stringify(msg));
    return true;
  }
}
