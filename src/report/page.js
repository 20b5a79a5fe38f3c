// Sorting: a click (or Enter) on a header with data-col sorts the body rows by that cell, ascending, then
// descending on the next click. Numbers compare as numbers; an empty data-v (no value) always goes last.
(function () {
  function value(row, col, numeric) {
    var cell = row.cells[col];
    var v = cell ? cell.getAttribute("data-v") : "";
    if (!numeric) return v === null ? cell.textContent : v;
    return v === null || v === "" ? NaN : parseFloat(v);
  }
  function sort(th) {
    var table = th.closest("table"), body = table.tBodies[0];
    var col = parseInt(th.getAttribute("data-col"), 10), numeric = th.hasAttribute("data-num");
    var dir = th.getAttribute("aria-sort") === "ascending" ? -1 : 1;
    table.querySelectorAll("th[aria-sort]").forEach(function (h) { h.removeAttribute("aria-sort"); });
    th.setAttribute("aria-sort", dir === 1 ? "ascending" : "descending");
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = value(a, col, numeric), y = value(b, col, numeric);
      if (numeric) {
        if (isNaN(x) || isNaN(y)) return (isNaN(x) ? 1 : 0) - (isNaN(y) ? 1 : 0);
        return dir * (x - y);
      }
      return dir * x.localeCompare(y);
    });
    rows.forEach(function (r) { body.appendChild(r); });
  }
  document.querySelectorAll("th[data-col]").forEach(function (th) {
    th.addEventListener("click", function () { sort(th); });
    th.addEventListener("keydown", function (e) { if (e.key === "Enter") sort(th); });
  });
})();
