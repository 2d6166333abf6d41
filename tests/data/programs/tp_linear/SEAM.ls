/PROG  SEAM
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "leadthrough SEAM";
PROG_SIZE	= 0;
FILE_NAME	= SEAM;
VERSION		= 0;
LINE_COUNT	= 14;
MEMORY_SIZE	= 0;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/MN
   1:  ! golden path ;
   2:  ! UT1 X = 0.000 mm ;
   3:  ! UT1 Y = 0.000 mm ;
   4:  ! UT1 Z = 0.000 mm ;
   5:  ! UT1 A = 0.000 deg ;
   6:  ! UT1 B = 0.000 deg ;
   7:  ! UT1 C = 0.000 deg ;
   8:  UFRAME_NUM=0 ;
   9:  UTOOL_NUM=1 ;
  10:  ! P1 ;
  11:J P[1] 10% FINE ;
  12:L P[2] 100mm/sec CNT50 ;
  13:  ! P2 ;
  14:L P[3] 100mm/sec FINE ;
/POS
P[1]{
   GP1:
	UF : 0, UT : 1,
	J1=     0.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=    90.000 deg,	J6=     0.000 deg
};
P[2]{
   GP1:
	UF : 0, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =   898.311  mm,	Y =   240.702  mm,	Z =  1299.000  mm,
	W =   180.000 deg,	P =     0.000 deg,	R =  -165.000 deg
};
P[3]{
   GP1:
	UF : 0, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =   805.404  mm,	Y =   465.000  mm,	Z =  1299.000  mm,
	W =   180.000 deg,	P =     0.000 deg,	R =  -150.000 deg
};
/END
