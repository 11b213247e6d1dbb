//! The HTML page every gbc report is: one style, figures side by side with captions.

use std::fmt::Write;

use super::markup::escape;

/// A whole HTML page: a title, an introduction (HTML) and sections (HTML), the one style
/// of every gbc report.
pub fn page(title: &str, intro: &str, sections: &[String]) -> String {
    let mut html = String::new();
    let _ = writeln!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n\
         <style>body{{font-family:sans-serif;max-width:1340px;margin:2em auto;padding:0 1em;color:#222}}\
         table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}\
         th{{background:#f3f3f3}}figure{{display:inline-block;margin:0.5em;vertical-align:top;width:640px}}\
         figcaption{{font-size:0.85em;color:#444}}.notes{{color:#8a4b00}}\
         pre{{background:#f6f6f6;padding:0.8em;white-space:pre-wrap;font-size:11px}}</style></head><body>",
        escape(title)
    );
    let _ = writeln!(html, "<h1>{}</h1>\n{intro}", escape(title));
    for section in sections {
        html.push_str(section);
    }
    html.push_str("</body></html>\n");
    html
}

/// A figure of the page: the SVG with its caption (plain text; none when empty).
pub fn figure(svg: &str, caption: &str) -> String {
    if caption.is_empty() {
        format!("<figure>{svg}</figure>\n")
    } else {
        format!(
            "<figure>{svg}<figcaption>{}</figcaption></figure>\n",
            escape(caption)
        )
    }
}
