// JSON-RPC 2.0 over the WebSocket at /ws (tools/contour-web/hub.hpp lists the methods).
// Reconnects by itself; `onState(up)` tells the page. Requests made while down fail at once
// (the page shows it): nothing is queued to run later on a machine tool.
export class Rpc {
  constructor(url) {
    this.url = url;
    this.nextId = 1;
    this.pending = new Map();
    this.handlers = new Map();
    this.onState = () => {};
    this.onOpen = async () => {};
    this.ws = null;
    this.up = false;
    this.closedByServer = '';
    this.connect();
  }

  connect() {
    const ws = new WebSocket(this.url);
    this.ws = ws;
    ws.onopen = async () => {
      this.up = true;
      this.closedByServer = '';
      try { await this.onOpen(); } catch (e) { console.warn('onOpen', e); }
      this.onState(true);
    };
    ws.onmessage = (ev) => this.dispatch(ev.data);
    ws.onclose = (ev) => {
      const was = this.up;
      this.up = false;
      if (ev.reason) this.closedByServer = ev.reason;
      for (const [, p] of this.pending) p.reject(new Error('connection to contour-web lost'));
      this.pending.clear();
      if (was) this.onState(false);
      else this.onState(false);
      setTimeout(() => this.connect(), 1000);
    };
  }

  dispatch(text) {
    let msg;
    try { msg = JSON.parse(text); } catch { return; }
    if (msg.id !== undefined && msg.id !== null && this.pending.has(msg.id)) {
      const p = this.pending.get(msg.id);
      this.pending.delete(msg.id);
      if (msg.error) p.reject(Object.assign(new Error(msg.error.message), { code: msg.error.code }));
      else p.resolve(msg.result);
      return;
    }
    if (msg.method) {
      const h = this.handlers.get(msg.method);
      if (h) h(msg.params);
    }
  }

  on(method, fn) { this.handlers.set(method, fn); }

  call(method, params) {
    if (!this.up || this.ws.readyState !== WebSocket.OPEN) {
      return Promise.reject(new Error('not connected to contour-web'));
    }
    const id = this.nextId++;
    const msg = { jsonrpc: '2.0', id, method };
    if (params !== undefined) msg.params = params;
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      this.ws.send(JSON.stringify(msg));
    });
  }

  // Fire and forget (dead-man keepalive).
  notify(method, params) {
    if (this.up && this.ws.readyState === WebSocket.OPEN) {
      const msg = { jsonrpc: '2.0', method };
      if (params !== undefined) msg.params = params;
      this.ws.send(JSON.stringify(msg));
    }
  }
}
