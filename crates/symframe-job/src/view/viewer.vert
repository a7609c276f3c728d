#version 300 es
// One tile's rectangle (map pixels, uRect = x0, y0, x1, y1) placed on the canvas by the view:
// a canvas pixel (device pixels, y down) shows map point uCenter + (pixel - uCanvas / 2) / uZoom.
uniform vec4 uRect;
uniform vec2 uCenter;
uniform float uZoom;
uniform vec2 uCanvas;
void main() {
    vec2 c = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    vec2 s = (mix(uRect.xy, uRect.zw, c) - uCenter) * uZoom + uCanvas * 0.5;
    gl_Position = vec4(s.x / uCanvas.x * 2.0 - 1.0, 1.0 - s.y / uCanvas.y * 2.0, 0.0, 1.0);
}
