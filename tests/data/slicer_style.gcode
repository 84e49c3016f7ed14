; written by hand in the style of a slicer's output, with arc fitting and no extruder
; (a plotter-like pass over rowc's facade: x-z plane, G18)
; external perimeters extrusion width = 0.45mm
G21 ; set units to millimeters
G90 ; use absolute coordinates
G18 ; the facade's plane
G1 Z520 F7200
;LAYER_CHANGE
;Z:520
G1 X1350 Y355 F7200
;TYPE:External perimeter
;WIDTH:0.45
G64
G1 X1650 F4800
G2 X1650 Z620 I0 K50
G1 X1350
G2 X1350 Z520 I0 K-50
;TYPE:Custom
G61
G1 Z560 F7200
M30
