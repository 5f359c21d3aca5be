// The one API client: bearer token, JSON in and out, errors turned into ApiError with a readable message.

const TOKEN_KEY = "cama.token";

/** An HTTP error from the backend; `body` is the parsed JSON body when there is one. */
export class ApiError extends Error {
  /**
   * @param {number} status
   * @param {string} message
   * @param {any} body
   */
  constructor(status, message, body) {
    super(message);
    this.status = status;
    this.body = body;
  }

  /** True for a 409 stale-version answer carrying the element as stored now. */
  get isConflict() {
    return this.status === 409;
  }
}

/**
 * A readable message from a FastAPI error body (string detail or a list of validation errors).
 * @param {any} body
 * @param {number} status
 */
export function errorMessage(body, status) {
  const detail = body && body.detail;
  if (typeof detail === "string") return detail;
  if (Array.isArray(detail)) {
    return detail
      .map((item) => {
        const field = (item.loc || []).slice(1).join(".") || "request";
        return String(item.msg).startsWith(`${field}:`) ? item.msg : `${field}: ${item.msg}`;
      })
      .join("; ");
  }
  return `HTTP ${status}`;
}

export class Api {
  constructor() {
    /** @type {string|null} */
    this.token = sessionStorage.getItem(TOKEN_KEY);
    /** @type {any} */
    this.me = null;
  }

  /** @param {string|null} token */
  setToken(token) {
    this.token = token;
    if (token) sessionStorage.setItem(TOKEN_KEY, token);
    else sessionStorage.removeItem(TOKEN_KEY);
  }

  /** Authorization headers for the current token. */
  authHeaders() {
    return this.token ? { Authorization: `Bearer ${this.token}` } : {};
  }

  /**
   * Call the API; resolves with the JSON body (null for 204), rejects with ApiError.
   * @param {string} method
   * @param {string} path e.g. "/api/sites"
   * @param {any} [body]
   * @param {Record<string, string|number|null|undefined>} [query]
   */
  async request(method, path, body, query) {
    const url = new URL(path, window.location.origin);
    for (const [key, value] of Object.entries(query || {})) {
      if (value !== undefined && value !== null && value !== "") url.searchParams.set(key, String(value));
    }
    const headers = { ...this.authHeaders() };
    if (body !== undefined) headers["Content-Type"] = "application/json";
    const response = await fetch(url, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    if (response.status === 204) return null;
    const text = await response.text();
    let parsed = null;
    try {
      parsed = text ? JSON.parse(text) : null;
    } catch {
      parsed = { detail: text };
    }
    if (!response.ok) {
      if (response.status === 401 && path !== "/api/auth/login") window.dispatchEvent(new Event("cama:logout"));
      throw new ApiError(response.status, errorMessage(parsed, response.status), parsed);
    }
    return parsed;
  }

  get(path, query) {
    return this.request("GET", path, undefined, query);
  }

  post(path, body, query) {
    return this.request("POST", path, body === undefined ? {} : body, query);
  }

  patch(path, body) {
    return this.request("PATCH", path, body);
  }

  del(path, query) {
    return this.request("DELETE", path, undefined, query);
  }

  /**
   * Log in and remember the token and user.
   * @param {string} username
   * @param {string} password
   */
  async login(username, password) {
    const token = await this.post("/api/auth/login", { username, password });
    this.setToken(token.access_token);
    this.me = await this.get("/api/auth/me");
    return this.me;
  }

  /** Revoke the token on the server (best effort: it may already be invalid) and forget it here. */
  logout() {
    if (this.token) {
      fetch("/api/auth/logout", { method: "POST", headers: this.authHeaders() }).catch(() => {});
    }
    this.setToken(null);
    this.me = null;
  }

  /**
   * Fetch an image (tile) with the token; resolves with its blob, or null for 404 (nothing there).
   * @param {string} path
   */
  async imageBlob(path) {
    const response = await fetch(path, { headers: this.authHeaders() });
    if (response.status === 404) return null;
    if (!response.ok) throw new ApiError(response.status, `tile ${path}: HTTP ${response.status}`, null);
    return response.blob();
  }
}
