// The place for a new panel of the shown run: addChartCard() puts a card after the others in #plots (the
// grid gives extra cards their own rows below) and returns the chart's element; draw it by registering a
// figure function with charts.js registerFigure(id, () => ({data, layout})), e.g. from its own module:
//   import { addChartCard } from "./panels.js";  import { registerFigure, baseLayout } from "./charts.js";
//   addChartCard("param-plot", "Estimated parameters", "estimate");
//   registerFigure("param-plot", () => ({ data: [...], layout: baseLayout("relative deviation") }));
import { termText } from "./glossary.js";

export function addChartCard(id, title, term = null, { wide = false } = {}) {
  const card = document.createElement("div");
  card.className = `card extra${wide ? " wide-extra" : ""}`;
  card.id = `card-${id}`;
  const h = document.createElement("h3");
  h.className = "card-title";
  h.textContent = `${title} `;
  if (term) {
    const help = document.createElement("span");
    Object.assign(help, { className: "help", tabIndex: 0 });
    help.dataset.term = term;
    help.setAttribute("aria-label", termText(term));
    h.append(help);
  }
  const plot = document.createElement("div");
  plot.id = id;
  plot.className = "plot";
  card.append(h, plot);
  document.getElementById("plots").append(card);
  return plot;
}

// Below 1100 px the side panels stack above the charts: the new-run form, the faults and the learnt furnace
// start closed there (their headings stay, one click opens them), so the charts come first (issue 27 item 10);
// wider, every panel is open.  Crossing the width sets them again; a click in between is the user's.
export const NARROW = "(max-width: 1099px)";

export function wirePanels() {
  const narrow = window.matchMedia(NARROW);
  const apply = () => {
    for (const d of document.querySelectorAll("details.panel[data-narrow=closed]")) d.open = !narrow.matches;
  };
  apply();
  narrow.addEventListener("change", apply);
}
