// The log-in form: trades a username and password for a token through the API client.
import { h } from "./dom.js";

/**
 * @param {HTMLElement} container
 * @param {import("./api.js").Api} api
 * @param {() => void} onLoggedIn
 */
export function mountLogin(container, api, onLoggedIn) {
  const username = h("input#username", { name: "username", autocomplete: "username", required: true });
  const password = h("input#password", {
    name: "password",
    type: "password",
    autocomplete: "current-password",
    required: true,
  });
  const error = h("div.form-error", { role: "alert" });
  const submit = h("button.primary#login-submit", { type: "submit" }, "Log in");
  const form = h(
    "form.login-card",
    {
      onsubmit: async (event) => {
        event.preventDefault();
        submit.disabled = true;
        error.textContent = "";
        try {
          await api.login(username.value, password.value);
          onLoggedIn();
        } catch (failure) {
          error.textContent = failure.message;
        } finally {
          submit.disabled = false;
        }
      },
    },
    h("h1", {}, "CAMA Studio"),
    h("p.muted", {}, "HD-map annotation over BEV rasters"),
    h("label", {}, "User name", username),
    h("label", {}, "Password", password),
    error,
    submit,
  );
  container.appendChild(h("div.center-page", {}, form));
  username.focus();
  return { destroy() {} };
}
