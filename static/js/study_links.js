// A study's page (admin): a participant's link is selected when its box gets
// focus, ready to copy.
for (const input of document.querySelectorAll("input.link")) {
  input.addEventListener("focus", () => input.select());
}
