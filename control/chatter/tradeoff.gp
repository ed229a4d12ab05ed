# Chatter vs contour error for the derivative-filter settings (control/CHATTER.md).
# Data: control/chatter/tradeoff.dat (control/chatter/tradeoff.sh). Usage, from the repository:
#   gnuplot control/chatter/tradeoff.gp      -> control/chatter/tradeoff.png
set terminal pngcairo size 1200,800 font ',11'
set output 'control/chatter/tradeoff.png'
set title "Table 2, CCC: command chatter through the daemon vs max contour error"
set xlabel 'command chatter through the daemon, worst axis: RMS of v(k)-v(k-1) (mm/s)'
set ylabel 'max contour error (um)'
set grid
set key bottom right
set logscale x
set xrange [0.5:30]
set yrange [40:90]
set arrow from 2,40 to 2,90 nohead dt 2 lw 2 lc rgb 'black'
set label 'goal 2 mm/s' at 2.05,88 font ',9'
set termoption noenhanced
# columns: 1 name, 2 blend_ms, 3 same_geometry, 4 lowpass_ms, 5-7 chatter x/y/z, 8 worst axis,
# 9 max step, 10 daemon max contour um, 11 seed Table 2 CCC um, 12 P/CCC, 13 eq11 CCC um, 14 P/CCC,
# 15-17 replay with command_applied chatter x/y/z, 18 its worst axis
plot 'control/chatter/tradeoff.dat' using 8:11 with points pt 7 ps 1.6 title 'seed-000 Table 2 (contour-sim, sharp corners, no acc/dec)', \
     ''                             using 8:11:1 with labels offset 1,0.8 left font ',9' notitle, \
     ''                             using 8:10 with points pt 5 ps 1.4 title 'daemon Table 2 (FIR 100 ms, G64 P50 blends)', \
     ''                             using 18:11 with points pt 6 ps 1.6 title 'x: chatter with command_applied (replay)', \
     53.926 * 1.1 with lines dt 2 lc rgb 'gray' title 'seed Table 2 + 10 % (the bar)'
