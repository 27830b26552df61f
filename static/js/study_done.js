// The end of a study sent back to its platform: after a short pause in which
// the participant can read their completion code, go back to Prolific (a
// redirect) or submit the MTurk assignment (a form POST to turkSubmitTo). The
// link or button on the page does the same at once.
const thanks = document.getElementById("thanks");
const target = thanks?.dataset.redirect;
const mturk = document.getElementById("mturk-submit");
const REDIRECT_AFTER_MS = 3000;

if (mturk) {
  setTimeout(() => mturk.requestSubmit(), REDIRECT_AFTER_MS);
} else if (target) {
  setTimeout(() => location.assign(target), REDIRECT_AFTER_MS);
}
