// Frame viewer: arrow keys move to the previous / next frame.
document.addEventListener("keydown", (event) => {
  if (event.target.closest("input, textarea, select")) return;
  const link = { ArrowLeft: "prev", ArrowRight: "next" }[event.key];
  const anchor = link && document.getElementById(link);
  if (anchor) anchor.click();
});
