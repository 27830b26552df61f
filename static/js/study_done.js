// The end of a study with a redirect (Prolific style): after a short pause in
// which the participant can read their completion code, go back to the
// recruiting platform with it. The link on the page does the same at once.
const thanks = document.getElementById("thanks");
const target = thanks?.dataset.redirect;
const REDIRECT_AFTER_MS = 3000;

if (target) {
  setTimeout(() => location.assign(target), REDIRECT_AFTER_MS);
}
