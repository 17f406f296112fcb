#!/usr/bin/python3
"""The device force along a deadband_lockstep run, undelayed against two delayed arms, and the
tool's height (issue 33's thirty-fifth stop).

Usage: felt_force_plot.py LOCKSTEP_OUT_DIR ARM_A ARM_B OUT.png
(LOCKSTEP_OUT_DIR from `deadband_lockstep --out`: reference.csv and ARM.csv). Also prints the
device force's RMS difference from the reference per half second, per arm.
"""
import sys
import numpy as np
import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt

d, a, b, out = sys.argv[1:5]
R = np.genfromtxt(f'{d}/reference.csv', delimiter=',', names=True)
A = np.genfromtxt(f'{d}/{a}.csv', delimiter=',', names=True)
B = np.genfromtxt(f'{d}/{b}.csv', delimiter=',', names=True)
K = ['device_fx', 'device_fy', 'device_fz']
fig, ax = plt.subplots(4, 1, figsize=(14, 12), sharex=True)
for axis, k in zip(ax, K):
    axis.plot(R['t_s'], R[k], label='undelayed')
    axis.plot(A['t_s'], A[k], label=a, alpha=.75)
    axis.plot(B['t_s'], B[k], label=b, alpha=.75)
    axis.set_ylabel(k + ' (N)')
    axis.legend(loc='upper right')
ax[3].plot(R['t_s'], R['tool_z'] * 1e3, label='tool z, undelayed')
ax[3].plot(A['t_s'], A['tool_z'] * 1e3, label='tool z, ' + a)
ax[3].plot(B['t_s'], B['tool_z'] * 1e3, label='tool z, ' + b)
ax[3].plot(B['t_s'], B['hand_z'] * 1e3, label='hand z', alpha=.5)
ax[3].set_ylabel('mm')
ax[3].set_xlabel('t (s)')
ax[3].legend(loc='upper right')
plt.tight_layout()
plt.savefig(out, dpi=70)
print('t (s)   ' + '   '.join(f'{n:>14s}' for n in (a, b)) + '   undelayed RMS |F|')
for t0 in np.arange(0, R['t_s'][-1], 0.5):
    m = (R['t_s'] >= t0) & (R['t_s'] < t0 + 0.5)
    e = [np.sqrt(np.mean(sum((R[k][m] - X[k][m]) ** 2 for k in K))) for X in (A, B)]
    print(f'{t0:4.1f}  ' + '   '.join(f'{v:12.3f} N' for v in e) +
          f'   {np.sqrt(np.mean(sum(R[k][m] ** 2 for k in K))):.3f} N')
