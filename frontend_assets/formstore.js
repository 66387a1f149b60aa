// The start form survives a reload: its values are kept in this browser (localStorage) and restored over
// the furnace's defaults, each one only if it still lies within the furnace's limits.
const KEY = "furnace-twin-start-form";

export function saveForm(form) {
  const data = {};
  for (const el of form.elements) {
    if (!el.name) continue;
    if (el.type === "radio") { if (el.checked) data[el.name] = el.value; } else data[el.name] = el.type === "checkbox" ? el.checked : el.value;
  }
  try { localStorage.setItem(KEY, JSON.stringify(data)); } catch (e) { /* private mode: not kept */ }
}

export function restoreForm(form) {
  let data = null;
  try { data = JSON.parse(localStorage.getItem(KEY) || "null"); } catch (e) { data = null; }
  if (!data) return;
  for (const el of form.elements) {
    if (!el.name || !(el.name in data)) continue;
    const v = data[el.name];
    if (el.type === "radio") el.checked = el.value === v;
    else if (el.tagName === "SELECT") { if ([...el.options].some((o) => o.value === v)) el.value = v; } // a choice still offered
    else if (el.type === "checkbox") el.checked = !!v;
    else if (el.type === "number") {
      const x = Number(v);
      const ok = v !== "" && Number.isFinite(x) && (el.min === "" || x >= Number(el.min)) && (el.max === "" || x <= Number(el.max));
      if (ok) el.value = v;
    } else el.value = v;
  }
}
