// REST client: JSON in and out, the API token of this tab, server errors as readable sentences.
import { $ } from "./page.js";

const TOKEN_KEY = "furnace-twin-token"; // sessionStorage: this tab only, never in the URL

export function token() { return sessionStorage.getItem(TOKEN_KEY) || ""; }

export function setToken(value) {
  if (value) sessionStorage.setItem(TOKEN_KEY, value); else sessionStorage.removeItem(TOKEN_KEY);
}

export function forgetOldToken() { localStorage.removeItem(TOKEN_KEY); } // an older dashboard kept it there

// One validation error as a sentence: "reference › point 2 › temperature: must be a number, got 'x'"
// (the server words the messages plainly, backend/messages.py; this names the field)
function formatValidation(e) {
  const loc = e.loc || [];
  const parts = [];
  for (let k = 0; k < loc.length; k++) {
    const p = loc[k];
    if (k === 0 && p === "body") continue;
    if (p === "transition" || p === parts[parts.length - 1]) continue; // tags of the reference union
    if (typeof p === "number" && parts[parts.length - 1] === "points") {
      parts.push(`point ${p + 1}`);
      if (loc[k + 1] === 0 || loc[k + 1] === 1) { parts.push(loc[k + 1] === 0 ? "time" : "temperature"); k += 1; }
      continue;
    }
    parts.push(String(p));
  }
  const msg = String(e.msg || "invalid").replace(/^Value error, /, "");
  return parts.length ? `${parts.join(" › ")}: ${msg}` : msg;
}

function formatDetail(detail) {
  if (typeof detail === "string") return detail;
  if (Array.isArray(detail)) return detail.map(formatValidation).join("; ");
  return JSON.stringify(detail);
}

export async function api(method, path, body, extraHeaders = {}) {
  const headers = { "Content-Type": "application/json", ...extraHeaders };
  if (token()) headers["X-API-Token"] = token(); // reads need it too when the server listens beyond loopback
  let r;
  try {
    r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  } catch (e) { throw new Error(`the server did not answer (${e.message})`); }
  let data = null;
  if (r.status !== 204) { try { data = await r.json(); } catch (e) { data = null; } }
  if (!r.ok) {
    const detail = data && data.detail !== undefined ? formatDetail(data.detail) : r.statusText;
    let text = detail;
    if (r.status === 401) {
      $("token-box").hidden = false;
      $("token").classList.add("need");
      text = token() ? "the API token is wrong: correct it in the \u201cAPI token\u201d field at the top right"
        : "this server needs its API token: enter it in the \u201cAPI token\u201d field at the top right";
    }
    const err = new Error(text);
    err.status = r.status;
    throw err;
  }
  if (data && typeof data === "object" && !Array.isArray(data)) Object.defineProperty(data, "httpStatus", { value: r.status });
  return data;
}
