// A top-down floor canvas in metres: +X to the right, +Z down the screen (the floor seen from
// above, Y towards the viewer, right-handed). heading_deg: 0 = facing +Z, 90 = facing +X.

export function headingDeg(dx, dz) {
  return (Math.atan2(dx, dz) * 180) / Math.PI;
}

export class FloorPad {
  // halfWidth: metres from the centre to the left/right edges
  constructor(canvas, halfWidth = 5) {
    this.canvas = canvas;
    this.halfWidth = halfWidth;
    this.center = [0, 0];
  }

  get scale() {
    return this.canvas.width / (2 * this.halfWidth); // pixels per metre
  }

  toFloor(clientX, clientY) {
    const r = this.canvas.getBoundingClientRect();
    const px = ((clientX - r.left) / r.width) * this.canvas.width;
    const py = ((clientY - r.top) / r.height) * this.canvas.height;
    return [this.center[0] + (px - this.canvas.width / 2) / this.scale, this.center[1] + (py - this.canvas.height / 2) / this.scale];
  }

  toPixels([x, z]) {
    return [this.canvas.width / 2 + (x - this.center[0]) * this.scale, this.canvas.height / 2 + (z - this.center[1]) * this.scale];
  }

  clear() {
    const ctx = this.canvas.getContext('2d');
    const { width: w, height: h } = this.canvas;
    ctx.fillStyle = '#1d2127';
    ctx.fillRect(0, 0, w, h);
    ctx.lineWidth = 1;
    const s = this.scale;
    const hw = w / 2 / s;
    const hh = h / 2 / s;
    for (let x = Math.ceil(this.center[0] - hw); x <= this.center[0] + hw; x++) {
      const [px] = this.toPixels([x, 0]);
      ctx.strokeStyle = x === 0 ? '#6b7480' : '#353b44';
      ctx.beginPath(); ctx.moveTo(px, 0); ctx.lineTo(px, h); ctx.stroke();
    }
    for (let z = Math.ceil(this.center[1] - hh); z <= this.center[1] + hh; z++) {
      const [, py] = this.toPixels([0, z]);
      ctx.strokeStyle = z === 0 ? '#6b7480' : '#353b44';
      ctx.beginPath(); ctx.moveTo(0, py); ctx.lineTo(w, py); ctx.stroke();
    }
    ctx.fillStyle = '#8a939e';
    ctx.font = '11px sans-serif';
    ctx.fillText('+X →', w - 38, h / 2 - 4);
    ctx.fillText('+Z ↓', w / 2 + 4, h - 6);
    ctx.fillText('1 m grid', 6, 14);
    return ctx;
  }

  polyline(ctx, points, color, width = 2) {
    if (points.length < 2) return;
    ctx.strokeStyle = color;
    ctx.lineWidth = width;
    ctx.beginPath();
    points.forEach((p, i) => {
      const [x, y] = this.toPixels(p);
      if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y);
    });
    ctx.stroke();
  }

  dot(ctx, p, color, r = 3) {
    const [x, y] = this.toPixels(p);
    ctx.fillStyle = color;
    ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.fill();
  }

  // an arrow at p facing heading (degrees), length in metres
  arrow(ctx, p, heading, color, label = '', length = 0.6) {
    const [x, y] = this.toPixels(p);
    const a = (heading * Math.PI) / 180;
    const dx = Math.sin(a) * length * this.scale;
    const dy = Math.cos(a) * length * this.scale;
    ctx.strokeStyle = color; ctx.fillStyle = color; ctx.lineWidth = 3;
    ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.fill();
    ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(x + dx, y + dy); ctx.stroke();
    const tip = [x + dx, y + dy];
    const back = Math.atan2(dy, dx);
    ctx.beginPath();
    ctx.moveTo(...tip);
    ctx.lineTo(tip[0] - 10 * Math.cos(back - 0.4), tip[1] - 10 * Math.sin(back - 0.4));
    ctx.lineTo(tip[0] - 10 * Math.cos(back + 0.4), tip[1] - 10 * Math.sin(back + 0.4));
    ctx.fill();
    if (label) {
      ctx.fillStyle = '#e8ecf1'; ctx.font = '12px sans-serif';
      ctx.fillText(label, x + 8, y - 8);
    }
  }
}
