// Help texts (GET /api/glossary): a "?" mark with data-term="..." (or data-metric="...") shows its text in
// a tooltip on hover, keyboard focus or a tap.  Marks added later (tables) work too (one delegated listener).
import { $, esc } from "./page.js";
import { state } from "./state.js";

export function termText(key) {
  const g = state.glossary;
  if (!g) return "";
  if (g.terms[key]) return g.terms[key];
  if (g.metrics[key]) return `${g.metrics[key].name}: ${g.metrics[key].meaning}`;
  return g.groups[key] || "";
}

export const metricName = (key) => (state.glossary && state.glossary.metrics[key] ? state.glossary.metrics[key].name : key);

// A help mark as HTML, for tables built in JS.
export const helpMark = (key) => `<span class="help" tabindex="0" role="button" data-term="${esc(key)}" aria-label="${esc(termText(key))}"></span>`;

function show(el) {
  const text = termText(el.dataset.term);
  if (!text) return;
  const tip = $("tip");
  tip.textContent = text;
  tip.hidden = false;
  const r = el.getBoundingClientRect();
  const w = Math.min(340, window.innerWidth - 16);
  tip.style.maxWidth = `${w}px`;
  const left = Math.max(8, Math.min(r.left, window.innerWidth - w - 8));
  tip.style.left = `${left}px`;
  const below = r.bottom + 6;
  tip.style.top = `${below}px`;
  const h = tip.getBoundingClientRect().height;
  if (below + h > window.innerHeight - 4) tip.style.top = `${Math.max(4, r.top - h - 6)}px`;
}

const hide = () => { $("tip").hidden = true; };

// Every static mark gets its text as an accessible name; the tooltip follows the pointer and the focus.
export function wireHelp() {
  for (const el of document.querySelectorAll(".help[data-term]")) {
    el.tabIndex = 0;
    el.setAttribute("role", "button");
    el.setAttribute("aria-label", termText(el.dataset.term));
  }
  const mark = (ev) => (ev.target.closest ? ev.target.closest(".help[data-term]") : null);
  document.addEventListener("mouseover", (ev) => { const m = mark(ev); if (m) show(m); });
  document.addEventListener("mouseout", (ev) => { if (mark(ev)) hide(); });
  document.addEventListener("focusin", (ev) => { const m = mark(ev); if (m) show(m); });
  document.addEventListener("focusout", (ev) => { if (mark(ev)) hide(); });
  document.addEventListener("click", (ev) => { const m = mark(ev); if (m) { ev.preventDefault(); show(m); } else hide(); });
  window.addEventListener("scroll", hide, true);
}
