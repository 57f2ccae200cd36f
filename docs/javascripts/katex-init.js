// Render the maths that pymdownx.arithmatex (generic mode) marks, with the KaTeX copy vendored
// beside this file (docs/javascripts/katex, MIT licence): the site needs no network.
function renderMaths() {
  document.querySelectorAll(".arithmatex").forEach(function (el) {
    renderMathInElement(el, {
      delimiters: [
        { left: "\\(", right: "\\)", display: false },
        { left: "\\[", right: "\\]", display: true },
      ],
      throwOnError: false,
    });
  });
}
if (typeof document$ !== "undefined") {
  document$.subscribe(renderMaths); // mkdocs-material's instant navigation
} else {
  document.addEventListener("DOMContentLoaded", renderMaths);
}
